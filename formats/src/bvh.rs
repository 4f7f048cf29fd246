//! BVH motion capture retargeted onto a rigged mesh: the skinning matrices that pose the mesh's skeleton like
//! the BVH performer, frame by frame.
//!
//! **Parsing.** `HIERARCHY` (`ROOT`/`JOINT name { OFFSET x y z CHANNELS n … }`, `End Site`) then `MOTION`
//! (`Frames: N`, `Frame Time: t`, N rows of channel values). Rotation channels are Euler angles in degrees,
//! composed in the order listed (`Zrotation Yrotation Xrotation` → `Rz · Ry · Rx`). BVH is Y-up. Frames are
//! kept every `round(fps / TARGET_FPS)`-th (mocap is recorded at 60–120 fps; the clips of this project are
//! game-rate); a first frame that jumps from the second by more than [`CALIBRATION_JUMP_DEG`] is dropped (the
//! calibration T-pose of CMU exports); the frame limit applies to the kept frames and is checked, with the number count the motion
//! section needs, before any frame is stored (whole frames beyond `Frames:` are ignored).
//!
//! **Joint mapping.** Both skeletons are matched to the body parts of [`PARTS`] by name (case and punctuation
//! ignored, a `mixamorig` prefix dropped): each part lists the BVH names it accepts (CMU and Biovision
//! conventions) and the rig names (Blender/Rigify as in Red Eclipse, Mixamo). Parts are assigned in table order
//! and a joint serves one part only, which settles `LeftShoulder` (the upper arm when the BVH has no `LeftArm`,
//! else the collar). The hips must map on both sides and at least [`MIN_PARTS`] parts in all, else the error
//! names the joints of both skeletons.
//!
//! **Rest-pose differences.** The BVH rest pose has every rotation zero (often a T-pose); the rig's is its bind
//! pose (often an A-pose, facing anywhere). Per part an alignment rotation `A` takes the BVH bone direction
//! (towards the part's child part) onto the rig's; the hips align a full frame (up towards the chest, side from
//! left to right thigh). A part whose child does not map reuses its parent part's `A`. At frame f a mapped rig
//! joint turns by `Δ = Q_f · A⁻¹` (`Q_f` the BVH joint's global rotation in rig axes) about its rest position,
//! which stays attached to its parent: `S_j(x) = Δ·(x − p_j) + S_parent(p_j)`; the hips add the BVH root's
//! displacement since the first frame, scaled by the ratio of hips-to-head heights. Unmapped rig joints follow
//! their parent rigidly. Bone lengths stay the rig's.

use std::path::Path;

use super::skeletal::{IDENTITY, Mat, apply, axis_rotation, mul};
use crate::error::{DataError, Result};

/// Largest BVH file read, in bytes.
pub const MAX_TEXT_BYTES: u64 = 256 << 20;
/// Frame rate the motion is thinned to (approximately: every `round(fps / TARGET_FPS)`-th frame).
pub const TARGET_FPS: f64 = 30.0;
/// Fewest mapped body parts for a retargeting (the hips among them).
pub const MIN_PARTS: usize = 4;
/// A first frame whose rotations differ from the second's by more than this many degrees at some channel is a
/// calibration pose (CMU exports start with a T-pose; mocap moves a few degrees per frame) and is dropped.
pub const CALIBRATION_JUMP_DEG: f64 = 45.0;
/// Most joints a BVH hierarchy may have.
pub const MAX_BVH_JOINTS: usize = 1024;

/// A body part: BVH name candidates, rig name candidates (`{S}` = `Left`/`Right`, `{s}` = `L`/`R`), the part
/// its bone points to, and the part to borrow an alignment from (`{p}` = `l_`/`r_` in part names).
pub struct Part {
    pub name: &'static str,
    pub bvh: &'static [&'static str],
    pub rig: &'static [&'static str],
    pub child: Option<&'static str>,
    pub parent: Option<&'static str>,
}

const fn part(
    name: &'static str,
    bvh: &'static [&'static str],
    rig: &'static [&'static str],
    child: Option<&'static str>,
    parent: Option<&'static str>,
) -> Part {
    Part {
        name,
        bvh,
        rig,
        child,
        parent,
    }
}

/// The mapping table, in assignment order. Sided parts are listed once and expanded for both sides.
pub const PARTS: &[Part] = &[
    part("hips", &["Hips", "Pelvis"], &["hips", "pelvis"], None, None),
    part(
        "spine",
        &["Ab", "LowerBack", "Spine"],
        &["spine", "abdomen"],
        Some("chest"),
        Some("hips"),
    ),
    part(
        "chest",
        &["Chest", "Spine1"],
        &["ribs", "chest", "Spine1", "Spine2"],
        Some("neck"),
        Some("spine"),
    ),
    part("neck", &["Neck"], &["neck"], Some("head"), Some("chest")),
    part("head", &["Head"], &["head"], None, Some("neck")),
    part(
        "{p}upper_arm",
        &["{S}Arm", "{S}UpArm", "{S}Shoulder"],
        &["upper_arm.{s}.01", "upper_arm.{s}", "{S}Arm"],
        Some("{p}forearm"),
        Some("{p}collar"),
    ),
    part(
        "{p}collar",
        &["{S}Collar", "{S}Shoulder"],
        &["shoulder.{s}", "clavicle.{s}", "{S}Shoulder"],
        Some("{p}upper_arm"),
        Some("chest"),
    ),
    part(
        "{p}forearm",
        &["{S}ForeArm", "{S}Elbow", "{S}LowArm"],
        &["forearm.{s}.01", "forearm.{s}", "{S}ForeArm", "LowerArm.{s}"],
        Some("{p}hand"),
        Some("{p}upper_arm"),
    ),
    part(
        "{p}hand",
        &["{S}Hand", "{S}Wrist"],
        &["hand.{s}", "{S}Hand"],
        None,
        Some("{p}forearm"),
    ),
    part(
        "{p}thigh",
        &["{S}UpLeg", "{S}Hip", "{S}Thigh"],
        &["thigh.{s}.01", "thigh.{s}", "{S}UpLeg"],
        Some("{p}shin"),
        Some("hips"),
    ),
    part(
        "{p}shin",
        &["{S}Leg", "{S}Knee", "{S}LowLeg", "{S}Shin"],
        &["shin.{s}.01", "shin.{s}", "{S}Leg"],
        Some("{p}foot"),
        Some("{p}thigh"),
    ),
    part(
        "{p}foot",
        &["{S}Foot", "{S}Ankle"],
        &["foot.{s}", "{S}Foot", "UpperFoot.{s}"],
        Some("{p}toe"),
        Some("{p}shin"),
    ),
    part(
        "{p}toe",
        &["{S}ToeBase", "{S}Toes", "{S}Toe"],
        &["toe.{s}", "{S}ToeBase"],
        None,
        Some("{p}foot"),
    ),
];

/// Lower-case letters and digits only, a `mixamorig` prefix dropped.
fn norm(name: &str) -> String {
    let n: String = name
        .chars()
        .filter(char::is_ascii_alphanumeric)
        .map(|c| c.to_ascii_lowercase())
        .collect();
    n.strip_prefix("mixamorig").map_or(n.clone(), str::to_owned)
}

/// A part name or alias with its side filled in (`side` 0 = left, 1 = right; unsided text unchanged).
fn sided(text: &str, side: usize) -> String {
    let (p, big, small) = [("l_", "Left", "L"), ("r_", "Right", "R")][side];
    text.replace("{p}", p).replace("{S}", big).replace("{s}", small)
}

/// One row of [`PARTS`] for one side, aliases normalised.
struct Row {
    name: String,
    bvh: Vec<String>,
    rig: Vec<String>,
    child: Option<String>,
    parent: Option<String>,
}

/// The expanded table, both sides of sided parts.
fn expanded() -> Vec<Row> {
    let mut out = Vec::new();
    for p in PARTS {
        let sides: &[usize] = if p.name.contains("{p}") { &[0, 1] } else { &[0] };
        for &side in sides {
            let f = |t: &str| sided(t, side);
            out.push(Row {
                name: f(p.name),
                bvh: p.bvh.iter().map(|a| norm(&f(a))).collect(),
                rig: p.rig.iter().map(|a| norm(&f(a))).collect(),
                child: p.child.map(f),
                parent: p.parent.map(f),
            });
        }
    }
    out
}

/// Part name → joint index, assigned in table order, each joint at most once.
fn assign(names: &[String], aliases: impl Fn(usize) -> Vec<String>, parts: usize) -> Vec<Option<usize>> {
    let normed: Vec<String> = names.iter().map(|n| norm(n)).collect();
    let mut taken = vec![false; names.len()];
    (0..parts)
        .map(|p| {
            let hit = aliases(p)
                .iter()
                .find_map(|a| (0..names.len()).find(|&j| !taken[j] && normed[j] == *a));
            if let Some(j) = hit {
                taken[j] = true;
            }
            hit
        })
        .collect()
}

#[derive(Debug, Clone, Copy)]
enum Channel {
    Pos(usize),
    Rot(usize),
}

#[derive(Debug)]
struct Joint {
    name: String,
    parent: Option<usize>,
    offset: [f64; 3],
    channels: Vec<Channel>,
}

/// A parsed BVH: the hierarchy, the kept frames' channel values and their rate.
#[derive(Debug)]
pub struct Bvh {
    joints: Vec<Joint>,
    /// Kept frames, each `channels` values.
    values: Vec<f64>,
    channels: usize,
    /// Frames kept, frames in the file, and the kept rate.
    pub frames: usize,
    pub file_frames: usize,
    pub fps: f32,
}

struct Tok<'a> {
    path: &'a Path,
    it: std::str::SplitAsciiWhitespace<'a>,
}

impl<'a> Tok<'a> {
    fn err(&self, field: &str, reason: impl Into<String>) -> DataError {
        DataError::new(self.path, field, reason)
    }
    fn next(&mut self, field: &str) -> Result<&'a str> {
        self.it.next().ok_or_else(|| self.err(field, "the file ends early"))
    }
    fn expect(&mut self, want: &str, field: &str) -> Result<()> {
        let t = self.next(field)?;
        if !t.eq_ignore_ascii_case(want) {
            return Err(self.err(field, format!("expected `{want}`, found `{t}`")));
        }
        Ok(())
    }
    fn float(&mut self, field: &str) -> Result<f64> {
        let t = self.next(field)?;
        match t.parse::<f64>() {
            Ok(v) if v.is_finite() => Ok(v),
            _ => Err(self.err(field, format!("`{t}` is not a finite number"))),
        }
    }
}

fn read_text(path: &Path) -> Result<String> {
    super::read_text_file(path, MAX_TEXT_BYTES.min(crate::limits::FILE_BYTES.get()))
}

fn joint_body(t: &mut Tok, joints: &mut Vec<Joint>, name: String, parent: Option<usize>) -> Result<()> {
    if joints.len() >= MAX_BVH_JOINTS {
        return Err(t.err("HIERARCHY", format!("more than {MAX_BVH_JOINTS} joints")));
    }
    let field = format!("joint {name}");
    t.expect("{", &field)?;
    t.expect("OFFSET", &field)?;
    let offset = [t.float(&field)?, t.float(&field)?, t.float(&field)?];
    t.expect("CHANNELS", &field)?;
    let n: usize = t
        .next(&field)?
        .parse()
        .map_err(|_| t.err(&field, "CHANNELS count is not a number"))?;
    if n > 6 {
        return Err(t.err(&field, format!("{n} channels, at most 6")));
    }
    let mut channels = Vec::with_capacity(n);
    for _ in 0..n {
        let c = t.next(&field)?;
        let axis = match c.as_bytes().first().map(u8::to_ascii_lowercase) {
            Some(b'x') => 0,
            Some(b'y') => 1,
            Some(b'z') => 2,
            _ => return Err(t.err(&field, format!("unknown channel `{c}`"))),
        };
        let lower = c.to_ascii_lowercase();
        channels.push(if lower.ends_with("position") {
            Channel::Pos(axis)
        } else if lower.ends_with("rotation") {
            Channel::Rot(axis)
        } else {
            return Err(t.err(&field, format!("unknown channel `{c}`")));
        });
    }
    let me = joints.len();
    joints.push(Joint {
        name,
        parent,
        offset,
        channels,
    });
    loop {
        let k = t.next(&field)?;
        if k == "}" {
            return Ok(());
        } else if k.eq_ignore_ascii_case("JOINT") {
            let child = t.next(&field)?.to_owned();
            joint_body(t, joints, child, Some(me))?;
        } else if k.eq_ignore_ascii_case("End") {
            t.expect("Site", &field)?;
            t.expect("{", &field)?;
            t.expect("OFFSET", &field)?;
            (0..3).try_for_each(|_| t.float(&field).map(|_| ()))?;
            t.expect("}", &field)?;
        } else {
            return Err(t.err(&field, format!("expected JOINT, End Site or `}}`, found `{k}`")));
        }
    }
}

/// Parse `path`, keeping every `round(fps / TARGET_FPS)`-th frame; more than `max_frames` kept frames is an
/// error before any is stored. With `motion = false` only the header is read (`values` stays empty).
pub fn parse(path: &Path, max_frames: usize, motion: bool) -> Result<Bvh> {
    let text = read_text(path)?;
    let mut t = Tok {
        path,
        it: text.split_ascii_whitespace(),
    };
    t.expect("HIERARCHY", "HIERARCHY")?;
    t.expect("ROOT", "ROOT")?;
    let mut joints = Vec::new();
    let root = t.next("ROOT")?.to_owned();
    joint_body(&mut t, &mut joints, root, None)?;
    t.expect("MOTION", "MOTION")?;
    t.expect("Frames:", "Frames")?;
    let file_frames: usize = t
        .next("Frames")?
        .parse()
        .map_err(|_| t.err("Frames", "not a frame count"))?;
    t.expect("Frame", "Frame Time")?;
    t.expect("Time:", "Frame Time")?;
    let dt = t.float("Frame Time")?;
    if !(dt.is_finite() && dt > 0.0 && 1.0 / dt <= super::skeletal::MAX_FPS) {
        return Err(t.err(
            "Frame Time",
            format!(
                "{dt} s is not a positive, finite frame time of at most {} fps",
                super::skeletal::MAX_FPS
            ),
        ));
    }
    let step = ((1.0 / dt / TARGET_FPS).round() as usize).max(1);
    let channels: usize = joints.iter().map(|j| j.channels.len()).sum();
    // The first two frames decide whether the first is a calibration pose (see `CALIBRATION_JUMP_DEG`).
    let mut head: Vec<f64> = Vec::with_capacity(2 * channels);
    for f in 0..file_frames.min(2) {
        for _ in 0..channels {
            head.push(t.float(&format!("frame {f}"))?);
        }
    }
    let is_rot: Vec<bool> = joints
        .iter()
        .flat_map(|j| j.channels.iter().map(|c| matches!(c, Channel::Rot(_))))
        .collect();
    let skip = usize::from(
        file_frames >= 2
            && (0..channels).any(|c| {
                let d = (head[c] - head[channels + c]).rem_euclid(360.0);
                is_rot[c] && d.min(360.0 - d) > CALIBRATION_JUMP_DEG
            }),
    );
    let frames = (file_frames - skip).div_ceil(step);
    if frames > max_frames {
        return Err(t.err(
            "Frames",
            format!("{frames} frames (of {file_frames}, every {step}th), more than the maximum of {max_frames}"),
        ));
    }
    let mut bvh = Bvh {
        joints,
        values: Vec::new(),
        channels,
        frames,
        file_frames,
        fps: (1.0 / (dt * step as f64)) as f32,
    };
    if !motion {
        return Ok(bvh);
    }
    // Exporters sometimes write a frame more than `Frames:` says: whole extra frames are ignored.
    let need = file_frames.saturating_sub(2).saturating_mul(channels);
    let have = t.it.clone().count();
    if have < need || (channels > 0 && !(have - need).is_multiple_of(channels)) {
        return Err(t.err(
            "MOTION",
            format!(
                "{file_frames} frames × {channels} channels need {} numbers, the file holds {}",
                need + head.len(),
                have + head.len()
            ),
        ));
    }
    bvh.values.reserve_exact(frames * channels);
    for f in 0..file_frames {
        let keep = f >= skip && (f - skip) % step == 0;
        if f < 2 {
            if keep {
                bvh.values.extend_from_slice(&head[f * channels..(f + 1) * channels]);
            }
            continue;
        }
        for _ in 0..channels {
            let v = t.float(&format!("frame {f}"))?;
            if keep {
                bvh.values.push(v);
            }
        }
    }
    Ok(bvh)
}

impl Bvh {
    /// Joint names in file order.
    pub fn names(&self) -> Vec<String> {
        self.joints.iter().map(|j| j.name.clone()).collect()
    }

    /// Global transforms of every joint at kept frame `f` (`None`: the rest pose).
    fn globals(&self, f: Option<usize>) -> Vec<Mat> {
        let row = f.map(|f| &self.values[f * self.channels..(f + 1) * self.channels]);
        let mut c = 0;
        let mut out: Vec<Mat> = Vec::with_capacity(self.joints.len());
        for j in &self.joints {
            let mut local = IDENTITY;
            let mut pos = j.offset;
            let mut rot = IDENTITY;
            for ch in &j.channels {
                let v = row.map_or(0.0, |r| r[c]);
                c += 1;
                match *ch {
                    Channel::Pos(a) => pos[a] = if row.is_some() { v } else { pos[a] },
                    Channel::Rot(a) => rot = mul(&rot, &axis_rotation(a, v)),
                }
            }
            for (r, row) in local.iter_mut().enumerate().take(3) {
                row[..3].copy_from_slice(&rot[r][..3]);
                row[3] = pos[r];
            }
            out.push(match j.parent {
                Some(p) => mul(&out[p], &local),
                None => local,
            });
        }
        out
    }
}

/// What [`retarget`] needs of a rigged mesh: joint names, parents (preceding their children) and rest
/// (bind) positions in the mesh's coordinates, and how BVH's Y-up axes map into them.
pub struct Rig<'a> {
    pub names: &'a [String],
    pub parents: &'a [Option<usize>],
    pub rest: &'a [[f64; 3]],
    /// `axes(p)` maps a BVH (Y-up) vector into the mesh's axes.
    pub axes: fn([f64; 3]) -> [f64; 3],
}

fn sub(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

fn cross(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

fn unit(a: [f64; 3]) -> Option<[f64; 3]> {
    let n = a.iter().map(|x| x * x).sum::<f64>().sqrt();
    (n > 1e-9).then(|| a.map(|x| x / n))
}

/// A rotation matrix (in a [`Mat`]) with columns `x, y, z`.
fn from_cols(x: [f64; 3], y: [f64; 3], z: [f64; 3]) -> Mat {
    let mut m = IDENTITY;
    for r in 0..3 {
        m[r][..3].copy_from_slice(&[x[r], y[r], z[r]]);
    }
    m
}

fn transpose3(m: &Mat) -> Mat {
    let mut t = IDENTITY;
    for r in 0..3 {
        for c in 0..3 {
            t[r][c] = m[c][r];
        }
    }
    t
}

/// An orthonormal frame from a main direction and a second, non-parallel one.
fn frame(main: [f64; 3], second: [f64; 3]) -> Option<Mat> {
    let y = unit(main)?;
    let z = unit(cross(second, y))?;
    Some(from_cols(cross(y, z), y, z))
}

/// The smallest rotation taking direction `a` onto `b`.
fn rotation_between(a: [f64; 3], b: [f64; 3]) -> Option<Mat> {
    let (a, b) = (unit(a)?, unit(b)?);
    let helper = if a[0].abs() < 0.9 {
        [1.0, 0.0, 0.0]
    } else {
        [0.0, 1.0, 0.0]
    };
    let side = unit(cross(a, b)).or_else(|| unit(cross(a, helper)))?;
    Some(mul(
        &from_cols(b, side, cross(b, side)),
        &transpose3(&from_cols(a, side, cross(a, side))),
    ))
}

/// Per kept frame, the skinning matrix of every rig joint (module doc).
pub fn retarget(path: &Path, bvh: &Bvh, rig: &Rig) -> Result<Vec<Vec<Mat>>> {
    let table = expanded();
    let bvh_names = bvh.names();
    let on_bvh = assign(&bvh_names, |p| table[p].bvh.clone(), table.len());
    let on_rig = assign(rig.names, |p| table[p].rig.clone(), table.len());
    let mapped: Vec<bool> = (0..table.len())
        .map(|p| on_bvh[p].is_some() && on_rig[p].is_some())
        .collect();
    let count = mapped.iter().filter(|&&m| m).count();
    if !mapped[0] || count < MIN_PARTS {
        let list = |v: &[String]| v.iter().take(24).cloned().collect::<Vec<_>>().join(", ");
        return Err(DataError::new(
            path,
            "joints",
            format!(
                "{count} body parts map (the hips {}, at least {MIN_PARTS} needed): BVH joints [{}] vs rig joints \
                 [{}]; see the mapping table in formats/src/bvh.rs",
                if mapped[0] { "among them" } else { "not" },
                list(&bvh_names),
                list(rig.names)
            ),
        ));
    }
    let index = |name: &str| table.iter().position(|t| t.name == name);
    let rest_b: Vec<[f64; 3]> = bvh
        .globals(None)
        .iter()
        .map(|m| (rig.axes)([m[0][3], m[1][3], m[2][3]]))
        .collect();
    let pos_b = |p: usize| on_bvh[p].map(|j| rest_b[j]);
    let pos_r = |p: usize| on_rig[p].map(|j| rig.rest[j]);
    let both = |p: Option<usize>| p.filter(|&p| mapped[p]);
    // Alignment per part: own bone, else the parent part's, else none.
    let mut align: Vec<Option<Mat>> = vec![None; table.len()];
    for p in 0..table.len() {
        if !mapped[p] {
            continue;
        }
        let own = if p == 0 {
            let up = both(index("chest")).or(both(index("spine")));
            let (l, r) = (both(index("l_thigh")), both(index("r_thigh")));
            up.and_then(|u| {
                let side_b = match (l, r) {
                    (Some(l), Some(r)) => sub(pos_b(r)?, pos_b(l)?),
                    _ => [1.0, 0.0, 0.0],
                };
                let side_r = match (l, r) {
                    (Some(l), Some(r)) => sub(pos_r(r)?, pos_r(l)?),
                    _ => [1.0, 0.0, 0.0],
                };
                let fb = frame(sub(pos_b(u)?, pos_b(0)?), side_b)?;
                let fr = frame(sub(pos_r(u)?, pos_r(0)?), side_r)?;
                Some(mul(&fr, &transpose3(&fb)))
            })
        } else {
            both(table[p].child.as_deref().and_then(index))
                .and_then(|c| rotation_between(sub(pos_b(c)?, pos_b(p)?), sub(pos_r(c)?, pos_r(p)?)))
        };
        align[p] = own.or_else(|| {
            let mut q = table[p].parent.as_deref().and_then(index);
            while let Some(pp) = q {
                if let Some(a) = align[pp] {
                    return Some(a);
                }
                q = table[pp].parent.as_deref().and_then(index);
            }
            None
        });
    }
    // Height ratio: hips to head (else neck, chest) on both skeletons.
    let len = |d: [f64; 3]| d.iter().map(|x| x * x).sum::<f64>().sqrt();
    let scale = ["head", "neck", "chest"]
        .iter()
        .find_map(|n| {
            let p = both(index(n))?;
            let (hb, hr) = (len(sub(pos_b(p)?, pos_b(0)?)), len(sub(pos_r(p)?, pos_r(0)?)));
            (hb > 1e-9).then(|| hr / hb)
        })
        .unwrap_or(1.0);
    // Rig joint → its part, when mapped.
    let mut part_of = vec![None; rig.names.len()];
    for p in 0..table.len() {
        if mapped[p] {
            part_of[on_rig[p].expect("mapped")] = Some(p);
        }
    }
    let axes_mat = {
        let c = |v| (rig.axes)(v);
        from_cols(c([1.0, 0.0, 0.0]), c([0.0, 1.0, 0.0]), c([0.0, 0.0, 1.0]))
    };
    let axes_inv = transpose3(&axes_mat);
    let root_b = on_bvh[0].expect("hips map");
    let first = bvh.globals(Some(0));
    let origin = [first[root_b][0][3], first[root_b][1][3], first[root_b][2][3]];
    let mut out = Vec::with_capacity(bvh.frames);
    for f in 0..bvh.frames {
        let g = bvh.globals(Some(f));
        let mut skin: Vec<Mat> = Vec::with_capacity(rig.names.len());
        for (j, part) in part_of.iter().enumerate() {
            let parent = rig.parents[j].map(|p| skin[p]);
            let s = match *part {
                None => parent.unwrap_or(IDENTITY),
                Some(p) => {
                    let mut q = mul(&mul(&axes_mat, &g[on_bvh[p].expect("mapped")]), &axes_inv);
                    (0..3).for_each(|k| q[k][3] = 0.0);
                    let mut delta = match align[p] {
                        Some(a) => mul(&q, &transpose3(&a)),
                        None => q,
                    };
                    let pj = rig.rest[j];
                    let mut anchor = parent.map_or(pj, |m| apply(&m, pj));
                    if p == 0 {
                        let here = [g[root_b][0][3], g[root_b][1][3], g[root_b][2][3]];
                        let d = (rig.axes)(sub(here, origin));
                        (0..3).for_each(|k| anchor[k] += scale * d[k]);
                    }
                    let turned = apply(&delta, pj);
                    (0..3).for_each(|k| delta[k][3] = anchor[k] - turned[k]);
                    delta
                }
            };
            skin.push(s);
        }
        out.push(skin);
    }
    Ok(out)
}

/// Hips → Spine → Chest → Neck → Head, and a left arm held sideways (+x, a T-pose) from the chest.
fn skeleton() -> &'static str {
    "HIERARCHY\nROOT Hips\n{\n OFFSET 0 0 0\n CHANNELS 6 Xposition Yposition Zposition Zrotation Yrotation Xrotation\n\
     JOINT Spine\n{\n OFFSET 0 2 0\n CHANNELS 3 Zrotation Yrotation Xrotation\n\
     JOINT Chest\n{\n OFFSET 0 2 0\n CHANNELS 3 Zrotation Yrotation Xrotation\n\
     JOINT Neck\n{\n OFFSET 0 2 0\n CHANNELS 3 Zrotation Yrotation Xrotation\n\
     JOINT Head\n{\n OFFSET 0 1 0\n CHANNELS 3 Zrotation Yrotation Xrotation\n End Site\n{\n OFFSET 0 1 0\n}\n}\n}\n\
     JOINT LeftArm\n{\n OFFSET 1 0 0\n CHANNELS 3 Zrotation Yrotation Xrotation\n\
     JOINT LeftForeArm\n{\n OFFSET 3 0 0\n CHANNELS 3 Zrotation Yrotation Xrotation\n\
     JOINT LeftHand\n{\n OFFSET 3 0 0\n CHANNELS 3 Zrotation Yrotation Xrotation\n End Site\n{\n OFFSET 1 0 0\n}\n}\n}\n}\n\
     }\n}\n}\n"
}

/// Text of a BVH for tests and fuzzing: the chain of [`skeleton`] with `rows` (27 values each: hips position + 8
/// joints × ZYX degrees) at `dt` seconds per frame.
#[doc(hidden)]
pub fn write_test_bvh(rows: &[Vec<f64>], dt: f64) -> String {
    let mut s = format!("{}MOTION\nFrames: {}\nFrame Time: {dt}\n", skeleton(), rows.len());
    for r in rows {
        s += &r.iter().map(f64::to_string).collect::<Vec<_>>().join(" ");
        s += "\n";
    }
    s
}

/// Joint names of a Rigify-style rig that [`write_test_bvh`]'s skeleton maps onto.
#[doc(hidden)]
pub const TEST_RIG: [&str; 8] = [
    "hips",
    "spine",
    "chest",
    "neck",
    "head",
    "upper_arm.L.01",
    "forearm.L.01",
    "hand.L",
];

#[cfg(test)]
mod tests {
    use super::*;
    use crate::iqm;
    use crate::skeletal::{ReadOptions, TakeSel};

    fn still() -> Vec<f64> {
        vec![0.0; 27]
    }

    #[test]
    fn parse_thins_to_game_rate_drops_calibration_and_bounds_frames() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("m.bvh");
        // 9 frames at 120 fps → every 4th: frames 0, 4, 8.
        let rows: Vec<Vec<f64>> = (0..9).map(|f| [vec![f as f64], vec![0.0; 26]].concat()).collect();
        std::fs::write(&path, write_test_bvh(&rows, 1.0 / 120.0)).unwrap();
        let b = parse(&path, 100, true).unwrap();
        assert_eq!((b.frames, b.file_frames, b.fps.round()), (3, 9, 30.0));
        assert_eq!(
            b.values.iter().step_by(27).copied().collect::<Vec<_>>(),
            [0.0, 4.0, 8.0]
        );
        // A first frame 90° away from the second is a calibration pose: dropped.
        let mut cal = rows.clone();
        cal[0][5] = 90.0;
        std::fs::write(&path, write_test_bvh(&cal, 1.0 / 120.0)).unwrap();
        let b = parse(&path, 100, true).unwrap();
        assert_eq!(b.values.iter().step_by(27).copied().collect::<Vec<_>>(), [1.0, 5.0]);
        // The limit counts kept frames and refuses before reading them.
        let e = parse(&path, 1, false).unwrap_err();
        assert!(
            e.field == "Frames" && e.reason.contains("more than the maximum of 1"),
            "{e}"
        );
        // A whole extra frame is ignored; a partial one or a missing one is an error.
        let text = write_test_bvh(&rows, 1.0 / 120.0);
        std::fs::write(&path, format!("{text}{}\n", vec!["0"; 27].join(" "))).unwrap();
        assert_eq!(parse(&path, 100, true).unwrap().file_frames, 9);
        std::fs::write(&path, format!("{text}0 0\n")).unwrap();
        assert_eq!(parse(&path, 100, true).unwrap_err().field, "MOTION");
        std::fs::write(&path, text.replace("Frames: 9", "Frames: 90000000")).unwrap();
        assert_eq!(parse(&path, usize::MAX, true).unwrap_err().field, "MOTION");
        std::fs::write(&path, text.replace("CHANNELS 3", "CHANNELS 9")).unwrap();
        assert!(parse(&path, 100, true).unwrap_err().reason.contains("at most 6"));
    }

    fn close(a: [f32; 3], b: [f32; 3]) -> bool {
        a.iter().zip(b).all(|(x, y)| (x - y).abs() < 1e-4)
    }

    #[test]
    fn retargets_by_name_across_rest_poses() {
        let dir = tempfile::tempdir().unwrap();
        let mesh = dir.path().join("body.iqm");
        std::fs::write(&mesh, iqm::write_test_rig(TEST_RIG)).unwrap();
        // Frame 2: the performer moved 1 along x and turned 90° about the vertical.
        let mut turn = still();
        turn[0] = 1.0;
        turn[4] = 90.0;
        std::fs::write(
            dir.path().join("turn.bvh"),
            write_test_bvh(&[still(), still(), turn], 1.0 / 30.0),
        )
        .unwrap();
        let takes = iqm::list_takes(&mesh).unwrap();
        assert_eq!((takes[0].name.as_str(), takes[0].frames), ("turn", 3), "{takes:?}");
        let (clip, _, _) = iqm::read(&mesh, &ReadOptions::default()).unwrap();
        // In the BVH's rest pose the rig's hanging arm is held sideways like the performer's: the hand joint goes
        // from (1, 0, 8) to (7, 0, 14) in Z-up, (7, 14, 0) in the clip's Y-up axes; the hips stay.
        assert!(close(clip.frame(0)[0], [7.0, 14.0, 0.0]), "{:?}", clip.frame(0)[0]);
        assert!(close(clip.frame(0)[1], [0.0, 10.0, 0.0]), "{:?}", clip.frame(0)[1]);
        // Turned 90° about the vertical through the hips and moved 1 along x: (1, 7, 14) Z-up → (1, 14, −7).
        assert!(close(clip.frame(2)[0], [1.0, 14.0, -7.0]), "{:?}", clip.frame(2)[0]);
        assert!(close(clip.frame(2)[1], [1.0, 10.0, 0.0]), "{:?}", clip.frame(2)[1]);
    }

    #[test]
    fn the_table_maps_cube2_player_bones() {
        // Bone names of Cube 2's snoutx10k player (IK helpers and fingers among them).
        let names: Vec<String> = [
            "Root",
            "SpineTwist",
            "Torso",
            "Hips",
            "Spine1",
            "ArmIK.L",
            "Spine2",
            "Neck",
            "Head",
            "UpperArm.L",
            "LowerArm.L",
            "Hand.L",
            "UpperArm.R",
            "LowerArm.R",
            "Hand.R",
            "Hip.L",
            "Thigh.L",
            "Shin.L",
            "UpperFoot.L",
            "LowerFoot.L",
            "Hip.R",
            "Thigh.R",
            "Shin.R",
            "UpperFoot.R",
            "LowerFoot.R",
        ]
        .map(str::to_owned)
        .to_vec();
        let rows = expanded();
        let got = assign(&names, |p| rows[p].rig.clone(), rows.len());
        let mapped = |part: &str| {
            let p = rows.iter().position(|r| r.name == part).unwrap();
            got[p].map(|j| names[j].as_str())
        };
        assert_eq!(mapped("hips"), Some("Hips"));
        assert_eq!(mapped("chest"), Some("Spine1"));
        assert_eq!(mapped("head"), Some("Head"));
        assert_eq!(mapped("l_forearm"), Some("LowerArm.L"));
        assert_eq!(mapped("r_hand"), Some("Hand.R"));
        assert_eq!(mapped("l_thigh"), Some("Thigh.L"));
        assert_eq!(mapped("r_shin"), Some("Shin.R"));
        assert_eq!(mapped("r_foot"), Some("UpperFoot.R"));
    }

    #[test]
    fn names_that_match_nothing_are_an_error_naming_both_skeletons() {
        let dir = tempfile::tempdir().unwrap();
        let mesh = dir.path().join("body.iqm");
        let rig = ["root", "b1", "b2", "b3", "b4", "b5", "b6", "b7"];
        std::fs::write(&mesh, iqm::write_test_rig(rig)).unwrap();
        std::fs::write(
            dir.path().join("walk.bvh"),
            write_test_bvh(&[still(), still()], 1.0 / 30.0),
        )
        .unwrap();
        let opts = ReadOptions {
            take: TakeSel::Name("walk".into()),
            ..ReadOptions::default()
        };
        let e = iqm::read(&mesh, &opts).unwrap_err();
        assert_eq!(e.field, "joints", "{e}");
        assert!(
            e.reason.contains("0 body parts map")
                && e.reason.contains("Hips, Spine, Chest")
                && e.reason.contains("root, b1, b2"),
            "{e}"
        );
        assert!(e.path.ends_with("walk.bvh"), "{e}");
    }
}
