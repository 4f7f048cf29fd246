//! How an import turns files into store clips: [`ImportOptions`] (window, stride, FPS tokens, vertex filter,
//! welding, per-file time limit, longest take) and their range checks.

use std::time::Duration;

use crate::clip::Clip;
use crate::error::{DataError, Result};
use crate::formats::skeletal;
use crate::limits::{FRAMES, MAX_P};
use crate::preprocess::{self, VertexFilter};

use super::DEFAULT_P;

/// Default [`ImportOptions::time_limit`]: reading and preprocessing one file normally takes well under a second;
/// ten minutes only stop a file that would never finish.
pub const FILE_TIME_LIMIT: Duration = Duration::from_secs(600);

/// Vertex welding before anything else (docs/method.md §2.1 sources with split seams).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub enum Weld {
    /// Keep the file's vertices as they are (default).
    #[default]
    Off,
    /// Merge vertices closer than this distance (in file units).
    Eps(f32),
}

impl Weld {
    /// `Eps` must be finite and ≥ 0 (`inf` would merge every vertex into one).
    pub fn validate(self) -> Result<()> {
        match self {
            Weld::Eps(e) if !(e.is_finite() && e >= 0.0) => {
                Err(DataError::new("weld", "epsilon", format!("{e} must be finite and ≥ 0")))
            }
            _ => Ok(()),
        }
    }

    /// Weld `clip` ([`preprocess::weld`]); the welded clip must still be a valid clip (at least 3 vertices).
    pub fn apply(self, clip: Clip) -> Result<Clip> {
        self.validate()?;
        let Weld::Eps(eps) = self else {
            return Ok(clip);
        };
        let welded = preprocess::weld(&clip, eps);
        welded
            .validate()
            .map_err(|e| DataError::new(&clip.source, format!("after welding at {eps}: {}", e.field), e.reason))?;
        Ok(welded)
    }
}

/// How files become store clips.
#[derive(Debug, Clone, PartialEq)]
pub struct ImportOptions {
    /// Accepted vertex counts (docs/method.md §2.2: 512..=4096).
    pub filter: VertexFilter,
    /// Window length T (docs/method.md §2.6: 16).
    pub frames: usize,
    /// Frames between window starts (docs/method.md §2.6: 1).
    pub stride: usize,
    /// Welding (default off).
    pub weld: Weld,
    /// FPS tokens P (docs/method.md §2.5: 512). A clip with fewer vertices gets its FPS order repeated cyclically
    /// (see [`crate::fps::farthest_point_sampling`]); the default filter rules that out.
    pub p: usize,
    /// Most time one source may take to read and preprocess; a slower one is rejected and the import goes on.
    /// Rust cannot stop a thread, so a reader past its limit keeps running in the background until it ends or the
    /// process exits.
    pub time_limit: Duration,
    /// Longest take read from a file with takes, in frames: a longer one is refused before its frames are
    /// baked (default [`skeletal::MAX_FRAMES`]; at most the current [`FRAMES`] limit).
    pub max_frames: usize,
    /// Play a take shorter than the window as a cycle when it loops (docs/method.md §2.6,
    /// [`crate::preprocess::loop_to`]); off by default, when such a take is rejected.
    pub loop_short: bool,
    /// Import only the sources of this shard (a share of the sources by a stable hash of their path; the
    /// [`super::shards`] module doc); `None` imports them all.
    pub shard: Option<super::shards::ShardSpec>,
}

impl Default for ImportOptions {
    fn default() -> Self {
        Self {
            filter: VertexFilter::default(),
            frames: 16,
            stride: 1,
            weld: Weld::Off,
            p: DEFAULT_P,
            time_limit: FILE_TIME_LIMIT,
            max_frames: skeletal::MAX_FRAMES,
            loop_short: false,
            shard: None,
        }
    }
}

impl ImportOptions {
    /// Range checks (F = the current [`FRAMES`] limit): 2 ≤ frames ≤ F, 1 ≤ stride ≤ F, 1 ≤ p ≤ [`MAX_P`],
    /// frames ≤ max_frames ≤ F, filter min ≤ max, a finite weld epsilon ≥ 0, a time limit above zero.
    pub fn validate(&self) -> Result<()> {
        let err = |field: &str, reason: String| Err(DataError::new("import options", field, reason));
        let max_frames = FRAMES.get_usize();
        if !(2..=max_frames).contains(&self.frames) {
            return err(
                "frames",
                format!(
                    "a window needs 2..={max_frames} frames, got {}{}",
                    self.frames,
                    FRAMES.hint()
                ),
            );
        }
        if !(1..=max_frames).contains(&self.stride) {
            return err("stride", format!("must be in 1..={max_frames}, got {}", self.stride));
        }
        check_p(self.p, "import options")?;
        if !(self.frames..=max_frames).contains(&self.max_frames) {
            return err(
                "max_frames",
                format!(
                    "{} must be in {}..={max_frames}: a take shorter than the window length {} cannot become a \
                     clip{}",
                    self.max_frames,
                    self.frames,
                    self.frames,
                    FRAMES.hint()
                ),
            );
        }
        if self.filter.min > self.filter.max {
            return err(
                "vertex filter",
                format!("min {} > max {}", self.filter.min, self.filter.max),
            );
        }
        if self.time_limit.is_zero() {
            return err("time limit", "must be above zero".into());
        }
        self.weld
            .validate()
            .map_err(|e| DataError::new("import options", "weld", e.reason))
    }
}

/// 1 ≤ p ≤ [`MAX_P`].
pub(super) fn check_p(p: usize, what: &str) -> Result<()> {
    if !(1..=MAX_P).contains(&p) {
        return Err(DataError::new(
            what,
            "p",
            format!("needs 1..={MAX_P} FPS tokens, got {p}"),
        ));
    }
    Ok(())
}
