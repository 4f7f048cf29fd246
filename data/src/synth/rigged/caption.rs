//! The caption of a rigged clip: the rig's words, a verb for its action on its template, the manner (pace or
//! force) and the direction it travels in the viewer's terms.

use super::actions::{Action, Motion};
use super::{Rig, Template};

/// The caption: the rig's words, then what it does, how, and which way it travels (`travel`: the centroid's
/// world displacement in x and z over the clip, viewer-relative as the procedural shapes' captions).
pub(super) fn caption(rig: &Rig, m: &Motion, travel: [f32; 2]) -> String {
    let t = rig.template;
    let side = if m.side > 0.0 { "right" } else { "left" };
    let pace = if m.pace < 0.85 {
        Some("slowly")
    } else if m.pace > 1.2 {
        Some("quickly")
    } else {
        None
    };
    let force = if m.amp < 0.85 {
        Some("gently")
    } else if m.amp > 1.2 {
        Some("wildly")
    } else {
        None
    };
    let (verb, manner): (String, Option<&str>) = match m.action {
        Action::Walk => (
            match t {
                Template::Insect => "scuttling",
                Template::Quadruped => "trotting",
                Template::Bird => "strutting",
                _ => "walking",
            }
            .into(),
            pace,
        ),
        Action::Run => (
            match t {
                Template::Quadruped => "galloping",
                Template::Insect => "scurrying",
                _ => "running",
            }
            .into(),
            pace,
        ),
        Action::Jump => (
            if m.travel > 0.0 {
                "leaping forward"
            } else {
                "jumping in place"
            }
            .into(),
            None,
        ),
        Action::Turn => {
            let way = if m.side > 0.0 { "right" } else { "left" };
            let around = if m.extent > 150.0 { " around" } else { "" };
            (format!("turning{around} to its {way}"), pace)
        }
        Action::Attack => (
            match t {
                Template::Biped | Template::MultiArm => format!("swinging its {side} arm in an attack"),
                Template::Quadruped => "lunging forward to bite".into(),
                Template::Insect => "striking with its front legs".into(),
                Template::Bird => "pecking at the ground".into(),
                Template::Snake => "rearing up and striking".into(),
            },
            force,
        ),
        Action::Wave => (
            match t {
                Template::Biped | Template::MultiArm => format!("waving its {side} hand"),
                Template::Quadruped => "wagging its tail".into(),
                Template::Insect => "waving its antennae".into(),
                Template::Bird => "flapping its wings in place".into(),
                Template::Snake => "swaying its head".into(),
            },
            force,
        ),
        Action::Fall => (
            match (t, m.extent as u32) {
                (Template::Insect, _) => "collapsing with its legs curling up".into(),
                (Template::Quadruped, _) => "collapsing onto its side".into(),
                (_, 0) => "falling forward".into(),
                (_, 1) => "falling over backward".into(),
                _ => format!("toppling over to its {}", if m.side > 0.0 { "left" } else { "right" }),
            },
            None,
        ),
        Action::Idle => (
            match t {
                Template::Snake => "lying still, swaying slightly",
                _ => "standing idle, breathing and looking around",
            }
            .into(),
            None,
        ),
        Action::Fly => ("flying".into(), pace),
        Action::Slither => ("slithering".into(), pace),
    };
    let moving = matches!(m.action, Action::Walk | Action::Run | Action::Fly | Action::Slither)
        || (m.action == Action::Jump && m.travel > 0.0);
    let dist = travel[0].hypot(travel[1]);
    let direction = if moving && dist > 0.1 * rig.length.max(rig.leg) {
        Some(if travel[0].abs() >= travel[1].abs() {
            if travel[0] > 0.0 { "to the right" } else { "to the left" }
        } else if travel[1] > 0.0 {
            "toward the viewer"
        } else {
            "away from the viewer"
        })
    } else {
        None
    };
    let words = rig.words.join(" ");
    let article = if words.starts_with(['a', 'e', 'i', 'o', 'u']) {
        "an"
    } else {
        "a"
    };
    let mut out = format!("{article} {words} {verb}");
    for w in [manner, direction].into_iter().flatten() {
        out.push(' ');
        out.push_str(w);
    }
    out
}
