//! Scenes around procedural clips (`data synth --scenes`; the scene a clip moves in is docs/method.md §6.5): a
//! floor under the clip and one or two pieces of furniture — a pillar beside it, a wall behind it, walls on both
//! sides, a low ceiling, a box or a table beside it — placed around the space the clip sweeps over all its frames
//! (its bounding box, plus a gap drawn per piece). The ground truth therefore never enters the scene: what a scene
//! tells a model is where the motion is free to go, and a completion that leaves that space collides. The floor's
//! top lies a hair below the clip's lowest point, so feet that stand on the ground touch it. Every part is a closed
//! cuboid ([`Scene::cuboid`]), and the caption names the furniture ("… beside a pillar and under a low ceiling").

use rand::Rng as _;

use crate::clip::Clip;
use crate::rng::DataRng;
use crate::scene::Scene;

type V3 = [f32; 3];

/// A piece of furniture.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Piece {
    Pillar,
    Wall,
    Corridor,
    Ceiling,
    Box,
    Table,
}

impl Piece {
    const ALL: [Piece; 6] = [
        Piece::Pillar,
        Piece::Wall,
        Piece::Corridor,
        Piece::Ceiling,
        Piece::Box,
        Piece::Table,
    ];

    fn phrase(self) -> &'static str {
        match self {
            Piece::Pillar => "beside a pillar",
            Piece::Wall => "in front of a wall",
            Piece::Corridor => "between two walls",
            Piece::Ceiling => "under a low ceiling",
            Piece::Box => "next to a box",
            Piece::Table => "next to a table",
        }
    }
}

/// The axis-aligned box every frame of `clip` lies in: (lowest, highest corner).
pub fn swept_box(clip: &Clip) -> (V3, V3) {
    crate::preprocess::bounds(&clip.vertices)
}

/// A scene around `clip` and the phrase its caption gains; every random draw comes from `r`.
pub fn furnish(clip: &Clip, r: &mut DataRng) -> (Scene, String) {
    let (lo, hi) = swept_box(clip);
    let size = (0..3).map(|k| hi[k] - lo[k]).fold(0.0f32, f32::max).max(1e-3);
    let floor = lo[1] - 2e-3 * size;
    let reach = 1.5 * size;
    let mut scene = Scene::cuboid(
        [lo[0] - reach, floor - 0.1 * size, lo[2] - reach],
        [hi[0] + reach, floor, hi[2] + reach],
    );
    let first = Piece::ALL[r.random_range(0..Piece::ALL.len())];
    let mut pieces = vec![first];
    if r.random_bool(0.5) {
        let second = Piece::ALL[r.random_range(0..Piece::ALL.len())];
        if second != first {
            pieces.push(second);
        }
    }
    for &piece in &pieces {
        for part in place(piece, lo, hi, floor, size, r) {
            scene = scene.with(&part);
        }
    }
    let phrase = pieces.iter().map(|p| p.phrase()).collect::<Vec<_>>().join(" and ");
    (scene, phrase)
}

/// The cuboids of `piece` outside the box `lo`–`hi` (standing on `floor` where it stands).
fn place(piece: Piece, lo: V3, hi: V3, floor: f32, size: f32, r: &mut DataRng) -> Vec<Scene> {
    let gap = size * r.random_range(0.03f32..0.15);
    // A side of the box: axis 0 (x) or 2 (z), below (false) or above (true).
    let (axis, above) = (if r.random_bool(0.5) { 0 } else { 2 }, r.random_bool(0.5));
    let other = 2 - axis;
    // From `gap` outside that side to `depth` further out along `axis`.
    let outside = |depth: f32, above: bool| match above {
        true => (hi[axis] + gap, hi[axis] + gap + depth),
        false => (lo[axis] - gap - depth, lo[axis] - gap),
    };
    let cuboid = |a: (f32, f32), o: (f32, f32), y: (f32, f32)| {
        let mut l = [0.0; 3];
        let mut h = [0.0; 3];
        (l[axis], h[axis]) = a;
        (l[other], h[other]) = o;
        (l[1], h[1]) = y;
        Scene::cuboid(l, h)
    };
    let along = |width: f32, r: &mut DataRng| {
        let c = r.random_range(lo[other]..=hi[other].max(lo[other]));
        (c - width / 2.0, c + width / 2.0)
    };
    let tall = hi[1] + size * r.random_range(0.3f32..1.0);
    match piece {
        Piece::Pillar => {
            let w = size * r.random_range(0.1f32..0.3);
            vec![cuboid(outside(w, above), along(w, r), (floor, tall))]
        }
        Piece::Wall | Piece::Corridor => {
            let t = 0.05 * size;
            let span = (lo[other] - size, hi[other] + size);
            let mut walls = vec![cuboid(outside(t, above), span, (floor, tall))];
            if piece == Piece::Corridor {
                walls.push(cuboid(outside(t, !above), span, (floor, tall)));
            }
            walls
        }
        Piece::Ceiling => {
            let y = hi[1] + gap;
            vec![Scene::cuboid(
                [lo[0] - size, y, lo[2] - size],
                [hi[0] + size, y + 0.05 * size, hi[2] + size],
            )]
        }
        Piece::Box => {
            let w = size * r.random_range(0.2f32..0.5);
            vec![cuboid(outside(w, above), along(w, r), (floor, floor + w))]
        }
        Piece::Table => {
            let (w, d) = (size * r.random_range(0.4f32..0.8), size * r.random_range(0.3f32..0.5));
            let top = floor + (hi[1] - floor).max(size * 0.2) * r.random_range(0.4f32..0.7);
            let (a, o) = (outside(d, above), along(w, r));
            let t = 0.04 * size;
            let mut parts = vec![cuboid(a, o, (top - t, top))];
            for (x, z) in [(a.0, o.0), (a.1 - t, o.0), (a.0, o.1 - t), (a.1 - t, o.1 - t)] {
                parts.push(cuboid((x, x + t), (z, z + t), (floor, top - t)));
            }
            parts
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Whether `p` lies strictly inside one of `scene`'s cuboids (each 8 consecutive vertices of a `furnish` scene).
    fn inside(scene: &Scene, p: V3) -> bool {
        scene.vertices.chunks_exact(8).any(|c| {
            let (l, h) = (c[0], c[7]);
            (0..3).all(|k| p[k] > l[k] && p[k] < h[k])
        })
    }

    #[test]
    fn furniture_stays_out_of_the_clip_and_the_floor_is_under_it() {
        let cfg = crate::synth::SynthConfig {
            clips: 60,
            max_vertices: 1024,
            ..Default::default()
        };
        let mut phrases = std::collections::BTreeSet::new();
        for i in 0..cfg.clips {
            let clip = crate::synth::generate_one(&cfg, i).unwrap();
            let mut r = crate::rng::rng(7, i as u64);
            let (scene, phrase) = furnish(&clip, &mut r);
            assert_eq!(scene.vertices.len() % 8, 0);
            assert!(clip.vertices.iter().all(|&v| !inside(&scene, v)), "clip {i}: {phrase}");
            // The floor (the first cuboid) lies under every vertex and touches the lowest one.
            let (lo, hi) = swept_box(&clip);
            let size = (0..3).map(|k| hi[k] - lo[k]).fold(0.0f32, f32::max);
            let top = scene.vertices[7][1];
            assert!(
                top < lo[1] && lo[1] - top < 3e-3 * size,
                "clip {i}: {top} {lo:?} {size}"
            );
            phrases.insert(phrase.split(" and ").next().unwrap().to_owned());
        }
        assert_eq!(phrases.len(), Piece::ALL.len(), "{phrases:?}");
    }
}
