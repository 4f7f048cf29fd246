//! Size limits shared by the readers, the generator and the store. Each bounds what one file, flag or option can
//! make the program allocate or compute, and says why its value is safe for real data.
//!
//! The four a user with unusually large real data may need to raise are [`Limit`]s, adjustable for one process
//! (`any4d --limit-frames N …`, see [`set_from_cli`]) up to a hard ceiling; the readers ask for their current value.
//! The `MAX_*` constants are their defaults.

use std::sync::atomic::{AtomicU64, Ordering};

/// Most frames in one clip (a baked glTF animation, a procedural clip, a store window): 5.5 minutes at 30 fps,
/// far beyond the 16–31-frame windows of the method, while one bogus key time or flag cannot ask for millions.
pub const MAX_FRAMES: usize = 10_000;
/// Most vertex rows (frames × vertices) of one clip: 2^26 rows are 768 MiB of f32 coordinates.
pub const MAX_CLIP_VERTICES: usize = 1 << 26;
/// Most vertices of a procedural clip: the shapes are made for 512–4096 vertices; 2^16 leaves room and keeps one
/// clip's geometry work small.
pub const MAX_SYNTH_VERTICES: usize = 1 << 16;
/// Most procedural clips one synth run writes: 2^24 index rows and jobs stay within a few GiB of memory.
pub const MAX_SYNTH_CLIPS: usize = 1 << 24;
/// Most FPS tokens P per clip: the method uses 512; 2^16 bounds the index arrays and the O(P · N) sampling.
pub const MAX_P: usize = 1 << 16;
/// Most triangles a clip's static scene may have (every scene metric visits every triangle for every vertex).
pub const MAX_SCENE_TRIANGLES: usize = 1 << 16;

/// Default of [`FILE_BYTES`]: no clip file format we read needs more than 4 GiB for one clip.
pub const MAX_FILE_BYTES: u64 = 1 << 32;
/// Default of [`BUFFER_BYTES`]: 1 GiB per glTF buffer, about 90 million baked vec3 values.
pub const MAX_BUFFER_BYTES: u64 = 1 << 30;

/// A size limit adjustable at run time within `1..=ceiling`.
#[derive(Debug)]
pub struct Limit {
    /// The command-line flag that sets it.
    pub flag: &'static str,
    /// What it bounds, for messages.
    pub what: &'static str,
    /// The value when nobody sets it.
    pub default: u64,
    /// The most it can be set to: beyond it one clip would need more memory than any machine we target has.
    pub ceiling: u64,
    value: AtomicU64,
}

impl Limit {
    const fn new(flag: &'static str, what: &'static str, default: u64, ceiling: u64) -> Self {
        Self {
            flag,
            what,
            default,
            ceiling,
            value: AtomicU64::new(default),
        }
    }

    /// The current value.
    pub fn get(&self) -> u64 {
        self.value.load(Ordering::Relaxed)
    }

    /// The current value as a `usize` (the ceilings fit on every 64-bit target; saturates elsewhere).
    pub fn get_usize(&self) -> usize {
        usize::try_from(self.get()).unwrap_or(usize::MAX)
    }

    /// Sets the value; refused outside `1..=ceiling`, with the reason.
    pub fn set(&self, value: u64) -> Result<(), String> {
        if !(1..=self.ceiling).contains(&value) {
            return Err(format!(
                "{} {value}: {} must be in 1..={} (default {})",
                self.flag, self.what, self.ceiling, self.default
            ));
        }
        self.value.store(value, Ordering::Relaxed);
        Ok(())
    }

    /// " (raise with --flag)": appended to the messages that refuse an input over this limit.
    pub fn hint(&self) -> String {
        format!(" (raise with {})", self.flag)
    }
}

/// Most frames in one clip, a window or a generated clip; default [`MAX_FRAMES`], ceiling 10⁶ (9 hours at 30 fps).
pub static FRAMES: Limit = Limit::new("--limit-frames", "frames per clip", MAX_FRAMES as u64, 1_000_000);
/// Most vertex rows (frames × vertices) of one clip; default [`MAX_CLIP_VERTICES`], ceiling 2³² rows (48 GiB of
/// f32 coordinates).
pub static CLIP_VERTICES: Limit = Limit::new(
    "--limit-clip-vertices",
    "vertex rows (frames × vertices) per clip",
    MAX_CLIP_VERTICES as u64,
    1 << 32,
);
/// Most bytes read from one input file; default [`MAX_FILE_BYTES`], ceiling 64 GiB.
pub static FILE_BYTES: Limit = Limit::new("--limit-file-bytes", "bytes per input file", MAX_FILE_BYTES, 1 << 36);
/// Most bytes of one glTF buffer; default [`MAX_BUFFER_BYTES`], ceiling 16 GiB.
pub static BUFFER_BYTES: Limit = Limit::new(
    "--limit-buffer-bytes",
    "bytes per glTF buffer",
    MAX_BUFFER_BYTES,
    1 << 34,
);

/// Applies the command line's limit flags (`None` keeps a limit's current value).
pub fn set_from_cli(
    frames: Option<u64>,
    clip_vertices: Option<u64>,
    file_bytes: Option<u64>,
    buffer_bytes: Option<u64>,
) -> Result<(), String> {
    for (limit, value) in [
        (&FRAMES, frames),
        (&CLIP_VERTICES, clip_vertices),
        (&FILE_BYTES, file_bytes),
        (&BUFFER_BYTES, buffer_bytes),
    ] {
        if let Some(v) = value {
            limit.set(v)?;
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn limits_start_at_their_defaults_and_refuse_zero_and_values_above_the_ceiling() {
        // A private limit: the statics are shared by every test of this process.
        let l = Limit::new("--max-x", "things", 10, 100);
        assert_eq!(l.get(), 10);
        let e = l.set(0).unwrap_err();
        assert!(
            e.contains("--max-x 0") && e.contains("1..=100") && e.contains("default 10"),
            "{e}"
        );
        assert!(l.set(101).is_err());
        assert_eq!(l.get(), 10);
        l.set(100).unwrap();
        assert_eq!(l.get(), 100);
        assert_eq!(l.hint(), " (raise with --max-x)");
        for s in [&FRAMES, &CLIP_VERTICES, &FILE_BYTES, &BUFFER_BYTES] {
            assert!(
                s.default <= s.ceiling && usize::try_from(s.ceiling).is_ok(),
                "{}",
                s.flag
            );
        }
    }
}
