//! Captions for clips read from game and motion files, built from the asset name and the take name.
//!
//! Rule: both names are split into lower-case words (at `_`, `-`, `.`, spaces, digits and camelCase bounds;
//! trailing digits dropped: `walk01` → `walk`). Asset words in [`GENERIC`] (`mesh`, `body`, `tris`, …) are
//! dropped, `male`/`female` move to the front. The first take word found in [`MOTIONS`] gives the verb phrase
//! (a word glued from a motion and more, `runbackward`, counts as that motion when the motion word has at least
//! 3 letters, and a direction word that ends it counts as a direction), followed by the take's direction words
//! (`forward`, `left`, …): `a male player walking forward`,
//! `a deer galloping`. Without a known motion word the caption is the asset alone (`a drone`); without an asset
//! word it is `something <motion>`; with neither it is empty (unconditional).

use std::path::Path;

/// Asset-name words that say nothing about what the object is.
pub const GENERIC: &[&str] = &[
    "mesh",
    "model",
    "models",
    "tris",
    "body",
    "re",
    "lod",
    "skeletal",
    "cached",
    "dae",
    "pmd",
    "psa",
    "iqm",
    "md2",
    "md3",
    "md5mesh",
    "base",
    "final",
    "new",
    "anim",
    "anims",
    "animation",
    "object",
    "objects",
    "actor",
    "actors",
    "data",
    "usr",
    "share",
    "games",
    "art",
    "the",
    "v",
    "a",
    "hud",
    "stklib",
    "main",
];

/// Take words and the verb phrase each stands for.
pub const MOTIONS: &[(&str, &str)] = &[
    ("walk", "walking"),
    ("walking", "walking"),
    ("run", "running"),
    ("runcycle", "running"),
    ("running", "running"),
    ("sprint", "sprinting"),
    ("gallop", "galloping"),
    ("trot", "trotting"),
    ("canter", "cantering"),
    ("idle", "standing idle"),
    ("stand", "standing"),
    ("jump", "jumping"),
    ("crouch", "crouching"),
    ("dash", "dashing"),
    ("attack", "attacking"),
    ("melee", "fighting"),
    ("death", "dying"),
    ("die", "dying"),
    ("dying", "dying"),
    ("dead", "lying dead"),
    ("swim", "swimming"),
    ("fly", "flying"),
    ("punch", "punching"),
    ("kick", "kicking"),
    ("shoot", "shooting"),
    ("fire", "shooting"),
    ("primary", "attacking"),
    ("secondary", "attacking"),
    ("reload", "reloading"),
    ("pain", "flinching"),
    ("eat", "eating"),
    ("feed", "eating"),
    ("graze", "grazing"),
    ("sit", "sitting"),
    ("climb", "climbing"),
    ("wave", "waving"),
    ("dance", "dancing"),
    ("build", "building"),
    ("gather", "gathering"),
    ("chop", "chopping"),
    ("mine", "mining"),
    ("farm", "farming"),
    ("fishing", "fishing"),
    ("carry", "carrying"),
    ("throw", "throwing"),
    ("open", "opening"),
    ("close", "closing"),
    ("move", "moving"),
    ("turn", "turning"),
    ("fall", "falling"),
    ("sink", "sinking"),
    ("switch", "switching weapons"),
    ("slide", "sliding"),
    ("powerslide", "sliding"),
    ("wallrun", "running along a wall"),
    ("spin", "spinning"),
    ("winning", "celebrating"),
    ("losing", "sulking"),
    ("backpedal", "reversing"),
    ("cheering", "cheering"),
    ("roar", "roaring"),
    ("boxing", "boxing"),
];

const DIRECTIONS: &[&str] = &["forward", "backward", "backwards", "left", "right", "up", "down"];

/// Lower-case words of a name (see the module doc).
pub fn words(name: &str) -> Vec<String> {
    let mut out = Vec::new();
    let mut cur = String::new();
    let mut prev_lower = false;
    for c in name.chars() {
        let boundary = !c.is_alphabetic() || (c.is_uppercase() && prev_lower);
        if boundary && !cur.is_empty() {
            out.push(std::mem::take(&mut cur));
        }
        if c.is_alphabetic() {
            cur.extend(c.to_lowercase());
        }
        prev_lower = c.is_lowercase();
    }
    if !cur.is_empty() {
        out.push(cur);
    }
    out
}

/// The asset words of a name: [`words`] minus [`GENERIC`], `male`/`female` first.
pub fn asset_words(name: &str) -> Vec<String> {
    let mut w: Vec<String> = words(name)
        .into_iter()
        .filter(|x| !GENERIC.contains(&x.as_str()))
        .collect();
    w.dedup();
    w.sort_by_key(|x| !(x == "male" || x == "female"));
    w
}

/// A readable asset name for a file: the asset words of its stem, else of its folder, else of the folder above.
pub fn asset_of_path(path: &Path) -> String {
    let stem = path
        .file_name()
        .map(|n| n.to_string_lossy().split('.').next().unwrap_or_default().to_owned())
        .unwrap_or_default();
    let mut names = vec![stem];
    let mut p = path.parent();
    for _ in 0..2 {
        if let Some(d) = p {
            names.push(
                d.file_name()
                    .map(|n| n.to_string_lossy().into_owned())
                    .unwrap_or_default(),
            );
            p = d.parent();
        }
    }
    names
        .iter()
        .map(|n| asset_words(n))
        .find(|w| !w.is_empty())
        .map(|w| w.join(" "))
        .unwrap_or_default()
}

/// The caption for `asset` (already readable, may be empty) doing take `take` (see the module doc).
pub fn caption(asset: &str, take: &str) -> String {
    let tw = words(take);
    let exact = |w: &str| MOTIONS.iter().find(|(k, _)| *k == w).map(|(_, v)| *v);
    // `runbackward` → `run` + `backward`: the longest motion word of ≥ 3 letters the word starts with.
    let glued = |w: &str| {
        MOTIONS
            .iter()
            .filter(|(k, _)| k.len() >= 3 && w.len() > k.len() && w.starts_with(k))
            .max_by_key(|(k, _)| k.len())
            .map(|(k, v)| (*v, DIRECTIONS.iter().find(|d| w[k.len()..].ends_with(**d)).copied()))
    };
    let motion = tw.iter().find_map(|w| exact(w).map(|m| (m, None)).or_else(|| glued(w)));
    let mut dirs: Vec<&str> = motion.and_then(|(_, d)| d).into_iter().collect();
    dirs.extend(
        tw.iter()
            .filter(|w| DIRECTIONS.contains(&w.as_str()))
            .map(String::as_str),
    );
    let motion = motion.map(|(m, _)| m);
    let subject = if asset.is_empty() {
        String::new()
    } else {
        let article = if asset.starts_with(['a', 'e', 'i', 'o', 'u']) {
            "an"
        } else {
            "a"
        };
        format!("{article} {asset}")
    };
    match (subject.is_empty(), motion) {
        (true, None) => String::new(),
        (false, None) => subject,
        (s, Some(m)) => {
            let mut out = if s { "something".to_owned() } else { subject };
            out.push(' ');
            out.push_str(m);
            for d in dirs {
                out.push(' ');
                out.push_str(d);
            }
            out
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn captions_follow_the_rule() {
        assert_eq!(
            caption(&asset_words("RE_Player_male").join(" "), "walk_forward"),
            "a male player walking forward"
        );
        assert_eq!(caption("deer", "deer_run_01"), "a deer running");
        assert_eq!(caption("elephant", "idle"), "an elephant standing idle");
        assert_eq!(caption("drone", "frag_power"), "a drone");
        assert_eq!(caption("", "runcycle0"), "something running");
        assert_eq!(caption("male player", "runbackward0"), "a male player running backward");
        assert_eq!(caption("male player", "runstepleft0"), "a male player running left");
        // A glued word needs a motion of at least 3 letters at its start.
        assert_eq!(caption("fish", "fish_move"), "a fish moving");
        assert_eq!(caption("cat", "upset"), "a cat");
        assert_eq!(caption("", "Take 001"), "");
        assert_eq!(words("hudPistol-reload2"), ["hud", "pistol", "reload"]);
    }

    #[test]
    fn asset_names_skip_generic_words() {
        assert_eq!(asset_of_path(Path::new("/d/actors/drone/mesh.md5mesh")), "drone");
        assert_eq!(asset_of_path(Path::new("/m/soldiers/female/body.md2")), "female");
        assert_eq!(asset_of_path(Path::new("/s/deer/deer_mesh.dae.cached.pmd")), "deer");
        assert_eq!(asset_of_path(Path::new("/models/models/mesh.md2")), "");
    }
}
