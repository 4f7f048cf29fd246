//! Binary FBX files for tests and `bench data`: a skinned mesh on root joints moved by translation curves.

use super::TICKS_PER_SECOND;
use super::binary::{self, Node, Prop};

pub(super) fn node(name: &str, props: Vec<Prop>, children: Vec<Node>) -> Node {
    Node {
        name: name.into(),
        props,
        children,
    }
}

/// `Properties70` entry `P` of property `name` with `values`.
#[doc(hidden)]
pub fn p70_entry(name: &str, values: &[Prop]) -> Node {
    let mut props = vec![
        Prop::Str(name.into()),
        Prop::Str(String::new()),
        Prop::Str(String::new()),
    ];
    props.push(Prop::Str("A".into()));
    props.extend_from_slice(values);
    node("P", props, Vec::new())
}

/// The nodes of a test `.fbx`: one mesh model holding `positions` and triangles `faces`, vertex `v` fully
/// skinned to root joint `j<skin[v]>` (bind matrices the identity), and one animation stack `walk` whose
/// translation curves put joint `j` at `keys[f][j]` at frame `f` (30 frames per second).
#[doc(hidden)]
pub fn test_fbx_nodes(positions: &[[f32; 3]], faces: &[[u32; 3]], skin: &[u8], keys: &[Vec<[f32; 3]>]) -> Vec<Node> {
    let joints = keys.first().map_or(0, Vec::len) as i64;
    let obj = |kind: &str, id: i64, name: &str, class: &str, children: Vec<Node>| {
        let props = vec![
            Prop::Int(id),
            Prop::Str(format!("{name}\0\u{1}{kind}")),
            Prop::Str(class.into()),
        ];
        node(kind, props, children)
    };
    let link = |c: i64, p: i64, prop: Option<&str>| {
        let mut props = vec![
            Prop::Str(if prop.is_some() { "OP" } else { "OO" }.into()),
            Prop::Int(c),
            Prop::Int(p),
        ];
        props.extend(prop.map(|s| Prop::Str(s.into())));
        node("C", props, Vec::new())
    };
    let array = |name: &str, p: Prop| node(name, vec![p], Vec::new());
    let identity: Vec<f64> = (0..16).map(|k| if k % 5 == 0 { 1.0 } else { 0.0 }).collect();
    let mut polygon = Vec::new();
    for f in faces {
        polygon.extend([i64::from(f[0]), i64::from(f[1]), !i64::from(f[2])]);
    }
    let mut objects = vec![
        obj(
            "Geometry",
            1,
            "mesh",
            "Mesh",
            vec![
                array(
                    "Vertices",
                    Prop::Floats(positions.iter().flatten().map(|&x| f64::from(x)).collect()),
                ),
                array("PolygonVertexIndex", Prop::Ints(polygon)),
            ],
        ),
        obj("Model", 2, "mesh", "Mesh", Vec::new()),
        obj("Deformer", 3, "skin", "Skin", Vec::new()),
        obj("AnimationStack", 4, "walk", "", Vec::new()),
        obj("AnimationLayer", 5, "layer", "", Vec::new()),
    ];
    let mut links = vec![link(1, 2, None), link(2, 0, None), link(3, 1, None), link(5, 4, None)];
    let tick = (TICKS_PER_SECOND / 30.0) as i64;
    for j in 0..joints {
        let verts: Vec<i64> = (0..positions.len())
            .filter(|&v| i64::from(skin[v]) == j)
            .map(|v| v as i64)
            .collect();
        let weights = Prop::Floats(vec![1.0; verts.len()]);
        objects.push(obj("Model", 100 + j, &format!("j{j}"), "LimbNode", Vec::new()));
        objects.push(obj(
            "Deformer",
            200 + j,
            &format!("c{j}"),
            "Cluster",
            vec![
                array("Indexes", Prop::Ints(verts)),
                array("Weights", weights),
                array("Transform", Prop::Floats(identity.clone())),
                array("TransformLink", Prop::Floats(identity.clone())),
            ],
        ));
        objects.push(obj("AnimationCurveNode", 300 + j, "T", "", Vec::new()));
        links.extend([
            link(100 + j, 0, None),
            link(200 + j, 3, None),
            link(100 + j, 200 + j, None),
            link(300 + j, 5, None),
            link(300 + j, 100 + j, Some("Lcl Translation")),
        ]);
        for (a, axis) in ["d|X", "d|Y", "d|Z"].iter().enumerate() {
            let id = 400 + 3 * j + a as i64;
            let times = Prop::Ints((0..keys.len() as i64).map(|f| f * tick).collect());
            let values = Prop::Floats(keys.iter().map(|k| f64::from(k[j as usize][a])).collect());
            objects.push(obj(
                "AnimationCurve",
                id,
                "",
                "",
                vec![array("KeyTime", times), array("KeyValueFloat", values)],
            ));
            links.push(link(id, 300 + j, Some(axis)));
        }
    }
    let settings = node("Properties70", Vec::new(), vec![p70_entry("TimeMode", &[Prop::Int(6)])]);
    vec![
        node("GlobalSettings", Vec::new(), vec![settings]),
        node("Objects", Vec::new(), objects),
        node("Connections", Vec::new(), links),
    ]
}

/// A test `.fbx` ([`test_fbx_nodes`]) as FBX 7.4 with compressed arrays.
#[doc(hidden)]
pub fn write_test_fbx(positions: &[[f32; 3]], faces: &[[u32; 3]], skin: &[u8], keys: &[Vec<[f32; 3]>]) -> Vec<u8> {
    binary::write(7400, &test_fbx_nodes(positions, faces, skin, keys), true)
}
