//! The mutation engine shared by the stable fuzz tests (`fuzz_stable.rs`: pickles, glTF, OBJ, stores;
//! `fuzz_readers.rs`: every skeletal and scene reader): byte- and token-level mutations, error kinds and tallies.
#![allow(dead_code)]

use std::collections::BTreeMap;
use std::time::Duration;

use any4d_data::DataError;
use rand::Rng;
use rand_chacha::ChaCha8Rng;

pub const INTERESTING_U32: [u32; 10] = [0, 1, 2, 3, 0x7f, 0xff, 0xffff, 0x7fff_ffff, 0x8000_0000, 0xffff_ffff];
pub const INTERESTING_NUMBERS: [&str; 16] = [
    "0",
    "-1",
    "1",
    "2",
    "3",
    "4",
    "5",
    "99",
    "255",
    "4096",
    "65535",
    "4294967295",
    "1e8",
    "1e30",
    "-1e30",
    "0.5",
];
/// One byte-level mutation: a bit flip, an interesting byte, u32 or u64, a cut, a copied range, a crossover with
/// another seed, a truncation.
pub fn mutate_once(rng: &mut ChaCha8Rng, b: &mut Vec<u8>, seeds: &[Vec<u8>]) {
    let len = b.len();
    if len == 0 {
        b.extend_from_slice(&seeds[rng.random_range(0..seeds.len())]);
        return;
    }
    let at = rng.random_range(0..len);
    match rng.random_range(0..8) {
        0 => b[at] ^= 1 << rng.random_range(0..8),
        1 => b[at] = [0, 1, 0x7f, 0x80, 0xff][rng.random_range(0..5)],
        2 if len >= 4 => {
            let v = INTERESTING_U32[rng.random_range(0..INTERESTING_U32.len())];
            let at = rng.random_range(0..=len - 4);
            b[at..at + 4].copy_from_slice(&v.to_le_bytes());
        }
        3 if len >= 8 => {
            let v = if rng.random_bool(0.5) {
                u64::MAX
            } else {
                rng.random::<u64>() >> rng.random_range(0..64)
            };
            let at = rng.random_range(0..=len - 8);
            b[at..at + 8].copy_from_slice(&v.to_le_bytes());
        }
        4 => {
            let end = (at + rng.random_range(1..=16)).min(len);
            b.drain(at..end);
        }
        5 => {
            let from = rng.random_range(0..len);
            let end = (from + rng.random_range(1..=32)).min(len);
            let chunk = b[from..end].to_vec();
            b.splice(at..at, chunk);
        }
        6 => {
            let other = &seeds[rng.random_range(0..seeds.len())];
            if !other.is_empty() {
                let from = rng.random_range(0..other.len());
                b.truncate(at);
                b.extend_from_slice(&other[from..]);
            }
        }
        _ => b.truncate(at),
    }
}

/// Replace one run of digits (with its sign) by an interesting number.
pub fn replace_number(rng: &mut ChaCha8Rng, b: &mut Vec<u8>) {
    let starts: Vec<usize> = (0..b.len())
        .filter(|&i| b[i].is_ascii_digit() && (i == 0 || !b[i - 1].is_ascii_digit() && b[i - 1] != b'.'))
        .collect();
    if starts.is_empty() {
        return;
    }
    let s = starts[rng.random_range(0..starts.len())];
    let mut e = s;
    while e < b.len() && (b[e].is_ascii_digit() || b[e] == b'.' || b[e] == b'e' || b[e] == b'-') {
        e += 1;
    }
    let s = if s > 0 && b[s - 1] == b'-' { s - 1 } else { s };
    // Mostly integers: most glTF numbers are counts, offsets and indices.
    let pick = if rng.random_bool(0.8) {
        rng.random_range(0..12)
    } else {
        rng.random_range(0..INTERESTING_NUMBERS.len())
    };
    b.splice(s..e, INTERESTING_NUMBERS[pick].bytes());
}

/// The error field and the start of its reason with digits blanked (`meshes[#] POSITION (accessors[#]): is
/// VEC#`), to count where inputs stop.
pub fn kind(e: &DataError) -> String {
    let reason: String = e.reason.split_whitespace().take(4).collect::<Vec<_>>().join(" ");
    format!("{}: {reason}", e.field)
        .chars()
        .map(|c| if c.is_ascii_digit() { '#' } else { c })
        .collect()
}

/// Distinct error kinds a tally keeps.
pub const MAX_KINDS: usize = 10_000;

/// What one fuzzing run did.
pub struct Tally {
    pub runs: usize,
    pub ok: usize,
    pub slowest: Duration,
    pub elapsed: Duration,
    /// Error kind → inputs that stopped there.
    pub errors: BTreeMap<String, usize>,
}

impl Tally {
    /// The `n` most frequent error kinds.
    pub fn top_errors(&self, n: usize) -> String {
        let mut v: Vec<(&String, &usize)> = self.errors.iter().collect();
        v.sort_by(|a, b| b.1.cmp(a.1));
        v.iter()
            .take(n)
            .map(|(k, c)| format!("{c} × {k}"))
            .collect::<Vec<_>>()
            .join("; ")
    }
}

impl Tally {
    pub fn new() -> Self {
        Tally {
            runs: 0,
            ok: 0,
            slowest: Duration::ZERO,
            elapsed: Duration::ZERO,
            errors: BTreeMap::new(),
        }
    }

    /// Record one run of `input` that took `took`: a read (`Ok(None)`), an error of a kind, or a panic, which
    /// saves the input as `any4d-fuzz-<label>` in the temporary folder and fails the test naming it.
    pub fn record(&mut self, label: &str, input: &[u8], outcome: Result<Option<String>, String>, took: Duration) {
        match outcome {
            Ok(None) => self.ok += 1,
            Ok(Some(kind)) => self.error(kind),
            Err(message) => {
                let path = std::env::temp_dir().join(format!("any4d-fuzz-{label}"));
                std::fs::write(&path, input).unwrap();
                panic!(
                    "{label}: input {} panicked: {message}; input saved to {}",
                    self.runs,
                    path.display()
                );
            }
        }
        self.slowest = self.slowest.max(took);
        self.runs += 1;
    }

    /// Count one input that stopped with error `kind` (new kinds past [`MAX_KINDS`] count as "other": kinds can
    /// include input text).
    pub fn error(&mut self, kind: String) {
        let key = if self.errors.len() < MAX_KINDS || self.errors.contains_key(&kind) {
            kind
        } else {
            "(other)".to_string()
        };
        *self.errors.entry(key).or_default() += 1;
    }
}
