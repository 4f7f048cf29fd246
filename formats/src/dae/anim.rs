//! COLLADA animation: channels on the scene nodes' transform elements, animation clips as takes, sampling.

use std::collections::HashMap;

use roxmltree::Node;

use super::{DEFAULT_FPS, Doc, SceneNode, children};
use crate::error::Result;
use crate::skeletal::{IDENTITY, Mat, TakeInfo, mul};

/// Keys of one transform element of one node: the whole element or one of its values.
#[derive(Clone)]
pub(super) struct Channel {
    element: usize,
    /// The value animated, or `None` for all of the element's values.
    component: Option<usize>,
    width: usize,
    times: Vec<f64>,
    values: Vec<f64>,
    /// Per key: hold its value until the next key (`STEP`).
    step: Vec<bool>,
}

impl Channel {
    /// Write the values at time `t` (linear between keys, held outside them and after `STEP` keys) into `out`:
    /// all of the element's values, or its one animated value.
    fn sample(&self, t: f64, out: &mut [f64]) {
        let w = self.width;
        let after = self.times.partition_point(|&k| k <= t);
        let key = |i: usize| &self.values[i * w..(i + 1) * w];
        let (a, b, f) = if after == 0 {
            (key(0), key(0), 0.0)
        } else if after == self.times.len() || self.step[after - 1] {
            (key(after - 1), key(after - 1), 0.0)
        } else {
            let (t0, t1) = (self.times[after - 1], self.times[after]);
            let f = if t1 > t0 { (t - t0) / (t1 - t0) } else { 0.0 };
            (key(after - 1), key(after), f)
        };
        let target = match self.component {
            Some(c) => &mut out[c..=c],
            None => out,
        };
        for ((o, x), y) in target.iter_mut().zip(a).zip(b) {
            *o = x + f * (y - x);
        }
    }
}

/// A take: channels per scene node, first time and frame rate (in `info`).
pub(super) struct Take {
    pub info: TakeInfo,
    pub channels: HashMap<usize, Vec<Channel>>,
    pub start: f64,
}

/// Node `node`'s local transform at time `t` under `channels`.
pub(super) fn local(node: &SceneNode, channels: &[Channel], t: f64) -> Mat {
    let mut m = IDENTITY;
    let mut v = [0.0; 16];
    for (i, e) in node.elements.iter().enumerate() {
        let v = &mut v[..e.values.len()];
        v.copy_from_slice(&e.values);
        channels.iter().filter(|c| c.element == i).for_each(|c| c.sample(t, v));
        m = mul(&m, &e.matrix(v));
    }
    m
}

/// Index of a member selector (`X`, `ANGLE`, `(3)`, `(1)(2)`) into an element of `width` values.
fn member(sel: &str, width: usize) -> Option<usize> {
    let i = match sel {
        ".X" => 0,
        ".Y" => 1,
        ".Z" => 2,
        ".ANGLE" => 3,
        _ => {
            let idx: Vec<usize> = sel
                .strip_prefix('(')?
                .strip_suffix(')')?
                .split(")(")
                .map(|x| x.parse().ok())
                .collect::<Option<_>>()?;
            match idx.as_slice() {
                [i] => *i,
                [r, c] => r * 4 + c,
                _ => return None,
            }
        }
    };
    (i < width).then_some(i)
}

/// The channel of `<channel>` element `ch`, or `None` when it animates something that is not a transform
/// element of a scene node (a camera, a material, a node outside the scene).
fn channel(doc: &Doc, ch: Node) -> Result<Option<(usize, Channel)>> {
    let target = ch.attribute("target").unwrap_or_default();
    let field = || format!("<channel target={target:?}>");
    let Some((node_id, rest)) = target.split_once('/') else {
        return Ok(None);
    };
    let Some(n) = doc.nodes.iter().position(|n| n.id == Some(node_id)) else {
        return Ok(None);
    };
    let cut = rest.find(['.', '(']).unwrap_or(rest.len());
    let (sid, sel) = rest.split_at(cut);
    let Some(e) = doc.nodes[n].elements.iter().position(|e| e.sid == Some(sid)) else {
        return Ok(None);
    };
    let width = doc.nodes[n].elements[e].values.len();
    let component = if sel.is_empty() {
        None
    } else {
        Some(member(sel, width).ok_or_else(|| doc.err(field(), format!("member {sel:?} of a {width}-value element")))?)
    };
    let sampler = doc.url(ch, "source")?;
    let (mut times, mut values, mut step, mut stride) = (Vec::new(), Vec::new(), Vec::new(), 1);
    for input in children(sampler, "input") {
        let (floats, words, s) = doc.source(doc.url(input, "source")?)?;
        match input.attribute("semantic") {
            Some("INPUT") => times = floats,
            Some("OUTPUT") => (values, stride) = (floats, s),
            Some("INTERPOLATION") => step = words.iter().map(|w| *w == "STEP").collect(),
            _ => {}
        }
    }
    let w = if component.is_some() { 1 } else { width };
    if stride != w || values.len() != times.len() * w || times.is_empty() {
        return Err(doc.err(
            field(),
            format!(
                "{} key times and {} values of stride {stride} for {w} value(s) per key",
                times.len(),
                values.len()
            ),
        ));
    }
    if times.windows(2).any(|p| p[1] < p[0]) {
        return Err(doc.err(field(), "key times that go back"));
    }
    step.resize(times.len(), false);
    Ok(Some((
        n,
        Channel {
            element: e,
            component,
            width: w,
            times,
            values,
            step,
        },
    )))
}

/// Channels of animation element `anim` and of the animations nested in it.
fn gather(doc: &Doc, anim: Node, out: &mut Vec<(usize, Channel)>) -> Result<()> {
    for ch in children(anim, "channel") {
        out.extend(channel(doc, ch)?);
    }
    for nested in children(anim, "animation") {
        gather(doc, nested, out)?;
    }
    Ok(())
}

/// Frames per second: the key step when every key time lies on one grid of 10–120 per second, else 30.
fn frame_rate(times: &[f64]) -> f64 {
    let mut t: Vec<f64> = times.to_vec();
    t.sort_by(f64::total_cmp);
    t.dedup_by(|a, b| (*a - *b).abs() < 1e-6);
    let step = t.windows(2).map(|p| p[1] - p[0]).fold(f64::INFINITY, f64::min);
    let fps = 1.0 / step;
    let on_grid = t.iter().all(|x| {
        let k = (x - t[0]) / step;
        (k - k.round()).abs() < 1e-3
    });
    if on_grid && (10.0..=120.0).contains(&fps) {
        fps
    } else {
        DEFAULT_FPS
    }
}

fn take(name: String, list: Vec<(usize, Channel)>, span: Option<(f64, f64)>) -> Option<Take> {
    let times: Vec<f64> = list.iter().flat_map(|(_, c)| c.times.iter().copied()).collect();
    let lo = times.iter().copied().fold(f64::INFINITY, f64::min);
    let hi = times.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    if times.is_empty() || hi - lo < 1e-9 {
        return None;
    }
    let (start, end) = span.filter(|(a, b)| b > a).unwrap_or((lo, hi));
    let fps = frame_rate(&times);
    let frames = ((end - start) * fps).round() + 1.0;
    let mut channels: HashMap<usize, Vec<Channel>> = HashMap::new();
    for (n, c) in list {
        channels.entry(n).or_default().push(c);
    }
    Some(Take {
        info: TakeInfo {
            name,
            frames: if frames.is_finite() && frames < 1e15 {
                frames as usize
            } else {
                usize::MAX
            },
            fps: crate::skeletal::fps_or_unknown(fps),
            file: None,
        },
        channels,
        start,
    })
}

/// An animation clip's name, channels and `(start, end)` when it states them.
type ClipChannels = (String, Vec<(usize, Channel)>, Option<(f64, f64)>);

/// The file's animation clips, else one clip `all` of every animation.
fn clips(doc: &Doc) -> Result<Vec<ClipChannels>> {
    let clips: Vec<Node> = doc
        .root
        .children()
        .filter(|c| c.tag_name().name() == "library_animation_clips")
        .flat_map(|l| children(l, "animation_clip"))
        .collect();
    if clips.is_empty() {
        let mut all = Vec::new();
        for lib in children(doc.root, "library_animations") {
            for a in children(lib, "animation") {
                gather(doc, a, &mut all)?;
            }
        }
        return Ok(vec![("all".into(), all, None)]);
    }
    let mut out = Vec::new();
    for (i, clip) in clips.into_iter().enumerate() {
        let mut list = Vec::new();
        for inst in children(clip, "instance_animation") {
            gather(doc, doc.url(inst, "url")?, &mut list)?;
        }
        let time = |a: &str| {
            clip.attribute(a)
                .and_then(|v| v.parse::<f64>().ok())
                .filter(|v| v.is_finite())
        };
        let span = time("end").map(|e| (time("start").unwrap_or(0.0), e));
        let name = clip
            .attribute("name")
            .or(clip.attribute("id"))
            .map_or(format!("take{i}"), str::to_owned);
        out.push((name, list, span));
    }
    Ok(out)
}

/// The takes of the file: its animation clips, else `all`, each kept when its keys span more than one time.
pub(super) fn takes(doc: &Doc) -> Result<Vec<Take>> {
    Ok(clips(doc)?
        .into_iter()
        .filter_map(|(name, list, span)| take(name, list, span))
        .collect())
}

/// The animation clips whose keys all fall on one time (poses, not takes), by name.
pub(super) fn poses(doc: &Doc) -> Result<Vec<String>> {
    Ok(clips(doc)?
        .into_iter()
        .filter(|(_, list, _)| {
            let times = || list.iter().flat_map(|(_, c)| c.times.iter().copied());
            let lo = times().fold(f64::INFINITY, f64::min);
            let hi = times().fold(f64::NEG_INFINITY, f64::max);
            lo.is_finite() && hi - lo < 1e-9
        })
        .map(|(name, _, _)| name)
        .collect())
}
