//! The FBX reader on written files: baking, transform and axis conventions, and broken or hostile input.

use super::binary::Node;
use super::transform::euler;
use super::write::node;
use super::*;

const TRI: [[f32; 3]; 3] = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.5]];

/// Two joints, two frames: joint 0 still, joint 1 moving by (0.5, 0.25, 0).
fn keys() -> Vec<Vec<[f32; 3]>> {
    vec![vec![[0.0; 3], [0.0; 3]], vec![[0.0; 3], [0.5, 0.25, 0.0]]]
}

fn nodes() -> Vec<Node> {
    test_fbx_nodes(&TRI, &[[0, 1, 2]], &[0, 1, 1], &keys())
}

fn write_file(dir: &Path, bytes: &[u8]) -> std::path::PathBuf {
    let path = dir.join("guy.fbx");
    std::fs::write(&path, bytes).unwrap();
    path
}

fn bake(bytes: &[u8]) -> Result<(Clip, SkinStats, TakeInfo)> {
    let dir = tempfile::tempdir().unwrap();
    read(&write_file(dir.path(), bytes), &ReadOptions::default())
}

/// The object with id `id` among `nodes`' `Objects`.
fn object(nodes: &mut [Node], id: i64) -> &mut Node {
    let objects = nodes.iter_mut().find(|n| n.name == "Objects").unwrap();
    objects
        .children
        .iter_mut()
        .find(|o| o.props[0] == Prop::Int(id))
        .unwrap()
}

/// Add `Properties70` entries to a node (creating the block).
fn add_props(n: &mut Node, entries: Vec<Node>) {
    if n.child("Properties70").is_none() {
        n.children.push(node("Properties70", Vec::new(), Vec::new()));
    }
    let block = n.children.iter_mut().find(|c| c.name == "Properties70").unwrap();
    block.children.extend(entries);
}

fn floats(v: &[f64]) -> Vec<Prop> {
    v.iter().map(|&x| Prop::Float(x)).collect()
}

fn close(a: [f32; 3], b: [f32; 3]) -> bool {
    a.iter().zip(b).all(|(x, y)| (x - y).abs() < 1e-5)
}

#[test]
fn the_test_writer_round_trips_through_every_record_width_and_array_encoding() {
    let dir = tempfile::tempdir().unwrap();
    let path = write_file(dir.path(), &write_test_fbx(&TRI, &[[0, 1, 2]], &[0, 1, 1], &keys()));
    let takes = list_takes(&path).unwrap();
    assert_eq!(
        (takes.len(), takes[0].name.as_str(), takes[0].frames, takes[0].fps),
        (1, "walk", 2, 30.0)
    );
    let (clip, stats, _) = read(&path, &ReadOptions::default()).unwrap();
    assert_eq!((clip.frames, clip.n_vertices, stats.vertices), (2, 3, 3));
    assert_eq!(clip.faces, vec![[0, 1, 2]]);
    assert_eq!(clip.frame(0), &TRI);
    assert_eq!(clip.frame(1), &[[0.0, 0.0, 0.0], [1.5, 0.25, 0.0], [0.5, 1.25, 0.5]]);
    for (version, compress) in [(7100, false), (7400, true), (7500, false), (7700, true)] {
        let (other, _, _) = bake(&binary::write(version, &nodes(), compress)).unwrap();
        assert_eq!(
            other.vertices, clip.vertices,
            "version {version}, compressed {compress}"
        );
    }
}

#[test]
fn skinned_vertices_start_from_the_mesh_models_rest_transform_not_the_clusters_transform() {
    let mut n = nodes();
    add_props(
        object(&mut n, 2),
        vec![p70_entry("Lcl Translation", &floats(&[0.0, 0.0, 5.0]))],
    );
    // A cluster `Transform` that is not the mesh's transform (Blender writes it relative to the bone): not used.
    object(&mut n, 200).children[2] = node("Transform", vec![Prop::Floats(vec![2.0; 16])], Vec::new());
    let (clip, _, _) = bake(&binary::write(7400, &n, false)).unwrap();
    assert_eq!(clip.frame(0)[0], [0.0, 0.0, 5.0]);
    assert_eq!(clip.frame(1)[1], [1.5, 0.25, 5.0]);
}

#[test]
fn euler_orders_turn_the_first_letter_first() {
    let turn = |order| {
        let m = euler([90.0, 90.0, 0.0], order);
        skeletal::apply(&m, [0.0, 1.0, 0.0]).map(|x| x as f32)
    };
    // XYZ: x takes (0, 1, 0) to (0, 0, 1), then y to (1, 0, 0); ZYX: y leaves it, then x gives (0, 0, 1).
    assert!(close(turn(0), [1.0, 0.0, 0.0]), "{:?}", turn(0));
    assert!(close(turn(5), [0.0, 0.0, 1.0]), "{:?}", turn(5));
}

#[test]
fn pre_rotation_pivots_and_rotation_curves_place_a_joint() {
    let mut n = nodes();
    // Joint 1 turned a quarter about z before its own rotation, and about its pivot at (1, 0, 0): vertex 1 at
    // (1, 0, 0) stays on the pivot, vertex 2 at (0, 1, 0.5) swings to (0, −1, 0.5), then moves with the keys.
    add_props(
        object(&mut n, 101),
        vec![
            p70_entry("PreRotation", &floats(&[0.0, 0.0, 90.0])),
            p70_entry("RotationPivot", &floats(&[1.0, 0.0, 0.0])),
        ],
    );
    let (clip, _, _) = bake(&binary::write(7400, &n, false)).unwrap();
    assert!(close(clip.frame(0)[1], [1.0, 0.0, 0.0]), "{:?}", clip.frame(0));
    assert!(close(clip.frame(0)[2], [0.0, -1.0, 0.5]), "{:?}", clip.frame(0));
    assert!(close(clip.frame(1)[2], [0.5, -0.75, 0.5]), "{:?}", clip.frame(1));
}

#[test]
fn axis_systems_turn_to_y_up_and_a_mirror_reverses_windings() {
    let settings = |entries: Vec<Node>| {
        let mut n = nodes();
        let g = n.iter_mut().find(|x| x.name == "GlobalSettings").unwrap();
        g.children[0].children.extend(entries);
        bake(&binary::write(7400, &n, false)).unwrap().0
    };
    let int = |name: &str, v: i64| p70_entry(name, &[Prop::Int(v)]);
    // 3ds Max: z up, front −y.
    let z_up = settings(vec![int("UpAxis", 2), int("FrontAxis", 1), int("FrontAxisSign", -1)]);
    assert_eq!(z_up.frame(0)[2], [0.0, 0.5, -1.0]);
    assert_eq!(z_up.faces, vec![[0, 1, 2]]);
    let mirrored = settings(vec![int("CoordAxisSign", -1)]);
    assert_eq!(mirrored.frame(0)[1], [-1.0, 0.0, 0.0]);
    assert_eq!(mirrored.faces, vec![[0, 2, 1]]);
    let e = bake(&binary::write(
        7400,
        &{
            let mut n = nodes();
            let g = n.iter_mut().find(|x| x.name == "GlobalSettings").unwrap();
            g.children[0].children.push(int("UpAxis", 0));
            n
        },
        false,
    ))
    .unwrap_err();
    assert!(e.reason.contains("0, 1 and 2"), "{e}");
}

#[test]
fn the_take_span_and_frame_rate_come_from_the_stack_and_time_mode() {
    let mut n = nodes();
    let tick = (TICKS_PER_SECOND / 30.0) as i64;
    add_props(
        object(&mut n, 4),
        vec![
            p70_entry("LocalStart", &[Prop::Int(0)]),
            p70_entry("LocalStop", &[Prop::Int(4 * tick)]),
        ],
    );
    let (clip, _, info) = bake(&binary::write(7400, &n, true)).unwrap();
    // Five frames; the keys end at frame 1, so frames 2-4 hold the last key.
    assert_eq!((info.frames, clip.frames), (5, 5));
    assert_eq!(clip.frame(4), clip.frame(1));
    let g = n.iter_mut().find(|x| x.name == "GlobalSettings").unwrap();
    g.children[0].children = vec![
        p70_entry("TimeMode", &[Prop::Int(14)]),
        p70_entry("CustomFrameRate", &[Prop::Float(-3.0)]),
    ];
    let e = bake(&binary::write(7400, &n, true)).unwrap_err();
    assert!(e.field.contains("CustomFrameRate"), "{e}");
}

#[test]
fn every_truncation_is_an_error() {
    let bytes = binary::write(7500, &nodes(), true);
    // The footer after the closing record is not needed.
    let body = bytes.len() - 16;
    for len in 0..body {
        assert!(
            binary::parse("t.fbx", &bytes[..len]).is_err(),
            "a prefix of {len} bytes parsed"
        );
    }
    assert!(binary::parse("t.fbx", &bytes[..body]).is_ok());
}

#[test]
fn headers_versions_and_encodings_are_checked() {
    let e = binary::parse("a.fbx", b"; FBX 7.5.0 project file\n").unwrap_err();
    assert!(e.reason.contains("ASCII"), "{e}");
    assert!(
        binary::parse("a.fbx", b"PK\x03\x04")
            .unwrap_err()
            .reason
            .contains("not a binary FBX")
    );
    let mut old = binary::write(7400, &nodes(), false);
    old[23..27].copy_from_slice(&6100u32.to_le_bytes());
    assert!(
        binary::parse("a.fbx", &old)
            .unwrap_err()
            .reason
            .contains("older than 7.0")
    );
    // One node `A` with one array property: FBX 7.4 puts its type byte at 27 + 3 × 4 + 1 + 1 = 41, then the
    // element count, the encoding and the stored byte count (4 bytes each), then the data at 54.
    let one = |p: Prop, compress: bool| binary::write(7400, &[node("A", vec![p], Vec::new())], compress);
    let set = |mut b: Vec<u8>, at: usize, v: &[u8]| {
        b[at..at + v.len()].copy_from_slice(v);
        b
    };
    let lying = set(one(Prop::Ints(vec![1, 2, 3]), false), 42, &1000u32.to_le_bytes());
    assert!(
        binary::parse("a.fbx", &lying)
            .unwrap_err()
            .reason
            .contains("stored in 24 bytes")
    );
    // A compressed array that claims 2^32 − 1 doubles: refused before inflating.
    let bomb = set(one(Prop::Floats(vec![0.0; 4]), true), 42, &u32::MAX.to_le_bytes());
    assert!(
        binary::parse("a.fbx", &bomb)
            .unwrap_err()
            .reason
            .contains("inflated in all")
    );
    // Bytes that are not zlib, and an unknown encoding.
    let junk = set(one(Prop::Floats(vec![0.0; 4]), true), 54, b"junk");
    assert!(binary::parse("a.fbx", &junk).unwrap_err().reason.contains("inflate"));
    let enc = set(one(Prop::Floats(vec![0.0; 4]), false), 46, &[7]);
    assert!(binary::parse("a.fbx", &enc).unwrap_err().reason.contains("encoding 7"));
}

#[test]
fn lying_records_and_deep_nesting_are_refused() {
    let base = binary::write(7400, &[node("A", vec![Prop::Int(1)], Vec::new())], false);
    // The record's end offset past the file, before its start, and a property count that does not fit.
    for (at, value, reason) in [
        (27, 1_000_000u32, "claims to end"),
        (27, 5, "claims to end"),
        (31, 2, "properties but its property bytes end"),
        (35, 100, "do not fit"),
    ] {
        let mut b = base.clone();
        b[at..at + 4].copy_from_slice(&value.to_le_bytes());
        let e = binary::parse("a.fbx", &b).unwrap_err();
        assert!(e.reason.contains(reason), "{reason}: {e}");
    }
    let mut deep = node("leaf", vec![Prop::Int(0)], Vec::new());
    for _ in 0..(binary::MAX_DEPTH + 2) {
        deep = node("n", Vec::new(), vec![deep]);
    }
    let e = binary::parse("a.fbx", &binary::write(7400, &[deep], false)).unwrap_err();
    assert!(e.reason.contains("nested"), "{e}");
}

#[test]
fn broken_scenes_get_reasons() {
    // A polygon naming a vertex the geometry lacks.
    let bad_index = test_fbx_nodes(&TRI, &[[0, 1, 7]], &[0, 1, 1], &keys());
    let e = bake(&binary::write(7400, &bad_index, false)).unwrap_err();
    assert!(e.reason.contains("names vertex 7"), "{e}");
    // A cluster weighting a vertex out of range.
    let mut n = nodes();
    object(&mut n, 200).children[0] = node("Indexes", vec![Prop::Ints(vec![9])], Vec::new());
    let e = bake(&binary::write(7400, &n, false)).unwrap_err();
    assert!(e.reason.contains("vertex 9"), "{e}");
    // A cluster without its joint.
    let mut n = nodes();
    let links = n.iter_mut().find(|x| x.name == "Connections").unwrap();
    links
        .children
        .retain(|c| c.props[1..3] != [Prop::Int(101), Prop::Int(201)]);
    let e = bake(&binary::write(7400, &n, false)).unwrap_err();
    assert!(e.reason.contains("no model"), "{e}");
    // Two models that are each other's parent.
    let mut n = nodes();
    let links = n.iter_mut().find(|x| x.name == "Connections").unwrap();
    for (c, p) in [(100, 101), (101, 100)] {
        links.children.insert(
            0,
            node(
                "C",
                vec![Prop::Str("OO".into()), Prop::Int(c), Prop::Int(p)],
                Vec::new(),
            ),
        );
    }
    let e = bake(&binary::write(7400, &n, false)).unwrap_err();
    assert!(e.reason.contains("cycle"), "{e}");
    // Key times and values of different lengths.
    let mut n = nodes();
    object(&mut n, 400).children[0] = node("KeyTime", vec![Prop::Ints(vec![0])], Vec::new());
    let e = bake(&binary::write(7400, &n, false)).unwrap_err();
    assert!(e.reason.contains("1 key times but 2 key values"), "{e}");
}

#[test]
fn a_static_mesh_is_not_a_clip_and_long_takes_are_refused() {
    let still = test_fbx_nodes(&TRI, &[[0, 1, 2]], &[0, 0, 0], &[vec![[0.0; 3]]]);
    let e = bake(&binary::write(7400, &still, false)).unwrap_err();
    assert!(e.reason.contains("static mesh is not a clip"), "{e}");
    let dir = tempfile::tempdir().unwrap();
    let path = write_file(dir.path(), &binary::write(7400, &nodes(), false));
    let opts = ReadOptions {
        max_frames: 1,
        ..ReadOptions::default()
    };
    let e = read(&path, &opts).unwrap_err();
    assert!(e.reason.contains("maximum of 1"), "{e}");
}

#[test]
fn a_stack_whose_keys_sit_on_one_time_is_a_pose_listed_as_such() {
    let dir = tempfile::tempdir().unwrap();
    let pose = vec![vec![[0.0; 3], [0.5, 0.25, 0.0]]];
    let path = write_file(
        dir.path(),
        &binary::write(7400, &test_fbx_nodes(&TRI, &[[0, 1, 2]], &[0, 1, 1], &pose), true),
    );
    assert!(list_takes(&path).unwrap().is_empty());
    assert_eq!(one_frame_takes(&path).unwrap().len(), 1);
    let path = write_file(dir.path(), &binary::write(7400, &nodes(), true));
    assert_eq!(
        (list_takes(&path).unwrap().len(), one_frame_takes(&path).unwrap().len()),
        (1, 0)
    );
}
