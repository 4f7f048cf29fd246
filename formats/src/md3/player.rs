//! Quake III players: the animations of an `animation.cfg` and the character assembled from its body parts.
//!
//! A player folder holds `lower.md3` (legs), `upper.md3` (torso) and usually `head.md3`, coarser copies of each
//! (`lower_1.md3`, …) and an `animation.cfg`. The game draws one character: the legs at the origin, the torso at
//! the legs' `tag_torso`, the head at the torso's `tag_head`, each part playing its own animation. [`Player`]
//! finds such a folder and [`read_player`] bakes it the same way; the cfg's animations also give the takes of a
//! body part read alone ([`part_ranges`]).

use std::path::{Path, PathBuf};

use super::{Md3File, Place};
use crate::clip::Clip;
use crate::error::{DataError, Result};
use crate::skeletal::{self, ReadOptions, SkinStats, TakeInfo, z_up_to_y_up};

/// Names of the animations of a Quake III player's `animation.cfg`, in the order of its numeric lines (Quake III
/// Arena's 25, then Team Arena's 6).
pub const ANIMATIONS: [&str; 31] = [
    "BOTH_DEATH1",
    "BOTH_DEAD1",
    "BOTH_DEATH2",
    "BOTH_DEAD2",
    "BOTH_DEATH3",
    "BOTH_DEAD3",
    "TORSO_GESTURE",
    "TORSO_ATTACK",
    "TORSO_ATTACK2",
    "TORSO_DROP",
    "TORSO_RAISE",
    "TORSO_STAND",
    "TORSO_STAND2",
    "LEGS_WALKCR",
    "LEGS_WALK",
    "LEGS_RUN",
    "LEGS_BACK",
    "LEGS_SWIM",
    "LEGS_JUMP",
    "LEGS_LAND",
    "LEGS_JUMPB",
    "LEGS_LANDB",
    "LEGS_IDLE",
    "LEGS_IDLECR",
    "LEGS_TURN",
    "TORSO_GETFLAG",
    "TORSO_GUARDBASE",
    "TORSO_PATROL",
    "TORSO_FOLLOWME",
    "TORSO_AFFIRMATIVE",
    "TORSO_NEGATIVE",
];

/// Largest `animation.cfg` read, in bytes.
pub const MAX_CFG_BYTES: u64 = 1 << 20;

/// What the torso plays while the legs play a `LEGS_*` animation, and the legs while the torso plays a `TORSO_*`
/// one (the game's standing poses).
const TORSO_IDLE: &str = "TORSO_STAND";
const LEGS_IDLE: &str = "LEGS_IDLE";

/// One animation line of an `animation.cfg`, its first frame already in the numbering of its part's file.
#[derive(Debug, Clone)]
struct Anim {
    name: &'static str,
    first: i128,
    /// Frames played (the magnitude of the line's count).
    count: usize,
    /// Frames looped after the end (Quake III's `loopFrames`), at most `count`.
    looping: usize,
    fps: f32,
    reverse: bool,
}

impl Anim {
    fn part(&self) -> Part {
        match self.name.split('_').next() {
            Some("LEGS") => Part::Lower,
            Some("TORSO") => Part::Upper,
            _ => Part::Both,
        }
    }

    /// The file frames of steps `0..steps` of this animation in a part of `frames` frames, or an error naming
    /// the animation when they fall outside it. Past its end the animation loops over its last `looping` frames
    /// or holds its last frame, as Quake III's `CG_RunLerpFrame` does; `step_fps` is the rate of the steps
    /// (another animation's when this one plays beside it).
    fn frames(&self, cfg: &Path, part: &str, frames: usize, steps: usize, step_fps: f32) -> Result<Vec<usize>> {
        let n = self.count.max(1);
        let end = usize::try_from(self.first).ok().and_then(|f| f.checked_add(n));
        let Some(first) = end.filter(|&e| e <= frames).map(|e| e - n) else {
            return Err(DataError::new(
                cfg,
                self.name,
                format!(
                    "frames {}..{} for the {part} body, but its .md3 has {frames}",
                    self.first,
                    self.first + n as i128
                ),
            ));
        };
        let rate = f64::from(self.fps) / f64::from(step_fps);
        Ok((0..steps)
            .map(|k| {
                // Saturating: a rate of up to 100,000 × steps cannot wrap; `as` saturates a too-large float.
                let f = (k as f64 * rate).floor() as usize;
                let f = match f {
                    f if f < n => f,
                    f if self.looping > 0 => n - self.looping + (f - n) % self.looping,
                    _ => n - 1,
                };
                first + if self.reverse { n - 1 - f } else { f }
            })
            .collect())
    }

    fn info(&self, cfg: &Path) -> TakeInfo {
        TakeInfo {
            name: self.name.to_owned(),
            frames: self.count,
            fps: self.fps,
            file: Some(cfg.to_path_buf()),
        }
    }
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Part {
    Lower,
    Upper,
    Both,
}

/// The animation lines of `text`. Each numeric line is `first frame, frame count, looping frames, frames per
/// second` of the next animation of [`ANIMATIONS`] (a negative count plays backwards); lines starting with a word
/// (`sex`, `footsteps`, …) and `//` comments are skipped. The `LEGS_*` first frames are moved down by
/// `LEGS_WALKCR`'s first frame minus `TORSO_GESTURE`'s, because `lower.md3` numbers its frames without the
/// torso's (as Quake III does).
fn animations(cfg: &Path, text: &str) -> Result<Vec<Anim>> {
    let mut rows: Vec<(i64, i64, i64, f32)> = Vec::new();
    for (n, line) in text.lines().enumerate() {
        let line = line.split("//").next().unwrap_or_default();
        let tokens: Vec<&str> = line.split_whitespace().collect();
        let Some(first) = tokens.first() else { continue };
        if !first.starts_with(|c: char| c.is_ascii_digit() || c == '-') {
            continue;
        }
        let err = |what: &str| DataError::new(cfg, format!("line {}", n + 1), what.to_owned());
        if tokens.len() < 4 {
            return Err(err(
                "an animation line needs first frame, frame count, looping frames and fps",
            ));
        }
        let int = |t: &str| {
            t.parse::<i64>()
                .map_err(|_| err(&format!("{t:?} is not a whole number")))
        };
        let fps: f32 = tokens[3]
            .parse()
            .map_err(|_| err(&format!("{:?} is not a frame rate", tokens[3])))?;
        let (start, count, looping) = (int(tokens[0])?, int(tokens[1])?, int(tokens[2])?);
        if start < 0 || !(fps.is_finite() && fps >= 0.0) {
            return Err(err(&format!("first frame {start} at {fps} fps")));
        }
        let fps = skeletal::check_fps(cfg, &format!("line {}", n + 1), f64::from(fps))?;
        // Quake III plays an animation listed at 0 fps at 1 fps (real players list unused ones as `0 0 0 0`).
        let fps = if fps == 0.0 { 1.0 } else { fps };
        if rows.len() == ANIMATIONS.len() {
            return Err(err(&format!(
                "more than the {} animations a player has",
                ANIMATIONS.len()
            )));
        }
        rows.push((start, count, looping, fps));
    }
    let index = |name: &str| ANIMATIONS.iter().position(|a| *a == name).expect("a known animation");
    let skip = match (rows.get(index("LEGS_WALKCR")), rows.get(index("TORSO_GESTURE"))) {
        (Some(legs), Some(torso)) => i128::from(legs.0) - i128::from(torso.0),
        _ => 0,
    };
    Ok(ANIMATIONS
        .iter()
        .zip(rows)
        .map(|(&name, (start, count, looping, fps))| {
            let count_abs = usize::try_from(count.unsigned_abs()).unwrap_or(usize::MAX);
            let mut anim = Anim {
                name,
                first: i128::from(start),
                count: count_abs,
                looping: usize::try_from(looping.max(0)).unwrap_or(usize::MAX).min(count_abs),
                fps,
                reverse: count < 0,
            };
            if anim.part() == Part::Lower {
                anim.first -= skip;
            }
            anim
        })
        .collect())
}

/// Read and parse the `animation.cfg` at `cfg`.
fn read_animations(cfg: &Path) -> Result<Vec<Anim>> {
    let text = String::from_utf8_lossy(&crate::read_file(cfg, MAX_CFG_BYTES)?).into_owned();
    animations(cfg, &text)
}

/// The takes an `animation.cfg` gives body part `part` (`lower` or `upper`) of a player whose `.md3` has
/// `frames` frames: `BOTH_*` animations belong to both parts, `TORSO_*` to the upper and `LEGS_*` to the lower
/// body. Animations of fewer than 2 frames are not takes; one that runs past the file's frames is an error
/// naming it.
pub fn cfg_takes(cfg: &Path, text: &str, part: &str, frames: usize) -> Result<Vec<TakeInfo>> {
    let anims = animations(cfg, text)?;
    Ok(ranges_of(cfg, &anims, part, frames)?
        .into_iter()
        .map(|r| r.info)
        .collect())
}

/// A take of one body part: what `data inspect` lists and the file frame of each of its steps.
pub(super) struct Range {
    pub(super) info: TakeInfo,
    pub(super) frames: Vec<usize>,
}

fn ranges_of(cfg: &Path, anims: &[Anim], part: &str, frames: usize) -> Result<Vec<Range>> {
    let want = if part == "lower" { Part::Lower } else { Part::Upper };
    anims
        .iter()
        .filter(|a| (a.part() == want || a.part() == Part::Both) && a.count >= 2)
        .map(|a| {
            Ok(Range {
                info: a.info(cfg),
                frames: a.frames(cfg, part, frames, a.count, a.fps)?,
            })
        })
        .collect()
}

/// The animations of one frame (poses, not takes) of body part `part` (`lower` or `upper`), or of the whole
/// player for `None`, by name; unused lines (0 frames) are not listed.
pub(super) fn one_frame_animations(cfg: &Path, part: Option<&str>) -> Result<Vec<String>> {
    let want = part.map(|p| if p == "lower" { Part::Lower } else { Part::Upper });
    Ok(read_animations(cfg)?
        .into_iter()
        .filter(|a| a.count == 1 && want.is_none_or(|w| a.part() == w || a.part() == Part::Both))
        .map(|a| a.name.to_owned())
        .collect())
}

/// The `animation.cfg` beside a player's body part (`lower.md3`, `upper_1.md3`, …), and which part the file is.
pub(super) fn part_cfg(path: &Path) -> Option<(PathBuf, &'static str)> {
    let stem = path.file_stem()?.to_string_lossy().to_ascii_lowercase();
    let part = ["lower", "upper"].into_iter().find(|p| part_stem(&stem, p))?;
    Some((beside(path, "animation.cfg")?, part))
}

/// The file named `name` (case-insensitive) in the folder of `path`, when it lies inside that folder
/// ([`skeletal::sidecar_inside`]).
fn beside(path: &Path, name: &str) -> Option<PathBuf> {
    let dir = match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d,
        _ => Path::new("."),
    };
    std::fs::read_dir(dir)
        .ok()?
        .flatten()
        .map(|e| e.path())
        .find(|p| p.file_name().is_some_and(|n| n.eq_ignore_ascii_case(name)) && skeletal::sidecar_inside(dir, p))
}

/// The takes of a body part read alone, from the player's `animation.cfg` (`None` when the file is not a
/// `lower`/`upper` part with a cfg beside it).
pub(super) fn part_ranges(path: &Path, frames: usize) -> Result<Option<Vec<Range>>> {
    let Some((cfg, part)) = part_cfg(path) else {
        return Ok(None);
    };
    ranges_of(&cfg, &read_animations(&cfg)?, part, frames).map(Some)
}

/// The files of a Quake III player whose folder holds `path`: `lower.md3` and `upper.md3` beside an
/// `animation.cfg`, and `head.md3` when there is one (names case-insensitive).
#[derive(Debug, Clone)]
pub struct Player {
    pub lower: PathBuf,
    pub upper: PathBuf,
    pub head: Option<PathBuf>,
    pub cfg: PathBuf,
}

impl Player {
    /// The player of the folder that holds `path`, if it is one.
    pub fn beside(path: &Path) -> Option<Player> {
        Some(Player {
            lower: beside(path, "lower.md3")?,
            upper: beside(path, "upper.md3")?,
            head: beside(path, "head.md3"),
            cfg: beside(path, "animation.cfg")?,
        })
    }

    /// The player that `path` stands for: its folder's, when `path` is that folder's `lower.md3`.
    pub fn of(path: &Path) -> Option<Player> {
        Player::beside(path).filter(|p| same_name(&p.lower, path))
    }
}

fn same_name(a: &Path, b: &Path) -> bool {
    a.file_name().zip(b.file_name()).is_some_and(|(a, b)| a == b)
}

/// Whether `path` is a part of a player (`lower`, `upper` or `head`, or one of their coarser copies
/// `lower_1.md3`, …) by its name.
pub fn is_part_name(path: &Path) -> bool {
    let Some(stem) = path.file_stem().map(|s| s.to_string_lossy().to_ascii_lowercase()) else {
        return false;
    };
    ["lower", "upper", "head"].iter().any(|p| part_stem(&stem, p))
}

/// Whether the lower-case `stem` names body part `part` or one of its coarser copies (`part`, `part_1`, …).
fn part_stem(stem: &str, part: &str) -> bool {
    stem.strip_prefix(part).is_some_and(|rest| {
        rest.is_empty()
            || rest
                .strip_prefix('_')
                .is_some_and(|d| !d.is_empty() && d.bytes().all(|b| b.is_ascii_digit()))
    })
}

/// A take of the assembled player: the animation that drives it and the file frames of each part per step.
pub(super) struct PlayerTake {
    pub(super) info: TakeInfo,
    lower: Vec<usize>,
    upper: Vec<usize>,
}

/// The takes of an assembled player whose legs have `lower` frames and torso `upper`: every animation of at
/// least 2 frames. A `BOTH_*` animation plays on both parts; while the legs play a `LEGS_*` one the torso plays
/// `TORSO_STAND`, and while the torso plays a `TORSO_*` one the legs play `LEGS_IDLE`, each at its own rate,
/// looping as the game loops it (frame 0 when the cfg does not list it).
pub(super) fn player_takes(cfg: &Path, lower: usize, upper: usize) -> Result<Vec<PlayerTake>> {
    let anims = read_animations(cfg)?;
    let idle = |name: &str| anims.iter().find(|a| a.name == name);
    let play = |a: Option<&Anim>, part: &str, frames: usize, steps: usize, fps: f32| match a {
        Some(a) => a.frames(cfg, part, frames, steps, fps),
        None => Ok(vec![0; steps]),
    };
    let mut out = Vec::new();
    for a in anims.iter().filter(|a| a.count >= 2) {
        let (on_lower, on_upper) = match a.part() {
            Part::Both => (Some(a), Some(a)),
            Part::Lower => (Some(a), idle(TORSO_IDLE)),
            Part::Upper => (idle(LEGS_IDLE), Some(a)),
        };
        // The driving animation first: its range check bounds the steps before the other part's are made.
        let (lower, upper) = if a.part() == Part::Upper {
            let upper = play(on_upper, "upper", upper, a.count, a.fps)?;
            (play(on_lower, "lower", lower, a.count, a.fps)?, upper)
        } else {
            let lower = play(on_lower, "lower", lower, a.count, a.fps)?;
            (lower, play(on_upper, "upper", upper, a.count, a.fps)?)
        };
        out.push(PlayerTake {
            info: a.info(cfg),
            lower,
            upper,
        });
    }
    Ok(out)
}

/// The takes of the player `p`, for `data inspect` and `--take`.
pub fn list_player_takes(p: &Player) -> Result<Vec<TakeInfo>> {
    let (lower, upper) = (Md3File::open(&p.lower)?, Md3File::open(&p.upper)?);
    Ok(player_takes(&p.cfg, lower.md3.frames, upper.md3.frames)?
        .into_iter()
        .map(|t| t.info)
        .collect())
}

/// Bake take `opts.take` of player `p` as one clip: per step the legs' vertices, the torso's placed at the legs'
/// `tag_torso` of that step and the head's (its first frame) at the torso's `tag_head`, in the order lower, upper,
/// head, turned Y-up. The clip is named after the player's folder.
pub fn read_player(p: &Player, opts: &ReadOptions) -> Result<(Clip, SkinStats, TakeInfo)> {
    let lower = Md3File::open(&p.lower)?;
    let upper = Md3File::open(&p.upper)?;
    let head = p.head.as_deref().map(Md3File::open).transpose()?;
    let takes = player_takes(&p.cfg, lower.md3.frames, upper.md3.frames)?;
    let infos: Vec<TakeInfo> = takes.iter().map(|t| t.info.clone()).collect();
    let take = &takes[skeletal::pick(&p.lower, &infos, &opts.take)?];
    let steps = take.info.frames;
    skeletal::check_frames(&p.lower, &take.info.name, steps, opts.max_frames)?;
    let torso_tag = lower.tag_index("tag_torso")?;
    let head_tag = head.as_ref().map(|_| upper.tag_index("tag_head")).transpose()?;
    let mut parts: Vec<&Md3File> = vec![&lower, &upper];
    parts.extend(&head);
    let n: usize = parts.iter().map(|p| p.md3.vertices()).sum();
    skeletal::check_rows(&p.lower, steps, n)?;
    // The head plays no animation: its first frame, read once.
    let mut head_points = Vec::new();
    if let Some(h) = &head {
        if h.md3.frames == 0 {
            return Err(DataError::new(&h.path, "num_frames", "the head has no frame"));
        }
        h.points(0, &mut head_points)?;
    }
    let mut faces = Vec::new();
    let mut base = 0u32;
    for part in &parts {
        faces.extend(part.md3.faces(base));
        base += part.md3.vertices() as u32;
    }
    let mut vertices = Vec::with_capacity(steps * n);
    let mut points = Vec::with_capacity(n);
    let y_up = |v: [f64; 3]| z_up_to_y_up(v).map(|x| x as f32);
    for k in 0..steps {
        let (fl, fu) = (take.lower[k], take.upper[k]);
        let torso = Place::ROOT.attach(&lower.tag(torso_tag, fl)?);
        points.clear();
        lower.points(fl, &mut points)?;
        vertices.extend(points.iter().map(|&v| y_up(v)));
        points.clear();
        upper.points(fu, &mut points)?;
        vertices.extend(points.iter().map(|&v| y_up(torso.point(v))));
        if let Some(t) = head_tag {
            let at = torso.attach(&upper.tag(t, fu)?);
            vertices.extend(head_points.iter().map(|&v| y_up(at.point(v))));
        }
    }
    let name = p
        .lower
        .parent()
        .and_then(Path::file_name)
        .map_or_else(|| skeletal::stem(&p.lower), |n| n.to_string_lossy().into_owned());
    let clip = Clip::new(name, vertices, steps, n, faces, "", p.lower.display().to_string())?;
    Ok((clip, SkinStats::default(), take.info.clone()))
}
