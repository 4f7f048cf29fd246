//! COLLADA `.dae` (1.4 and 1.5): node hierarchies holding meshes and skin controllers, animated by channels on
//! the nodes' transform elements, baked per frame.
//!
//! The scene is the visual scene `<scene>` instances (else the first). A node's local transform is the product,
//! in document order, of its `<matrix>` (row-major), `<translate>`, `<rotate>` (axis and angle in degrees) and
//! `<scale>` elements; a node's global transform is its parent's times its local one. Every `<instance_geometry>`
//! and `<instance_controller>` of the scene's nodes is read into one vertex list: triangles, polylists, polygons,
//! triangle strips and fans (split into fans; lines are not surfaces and are dropped). A rigid geometry's vertex
//! is `G(node) · v`; a skin's is `Σ_k w_k · G(joint_k) · IBM_k · BSM · v` (inverse bind matrices, bind shape
//! matrix), its joints found by `sid`, then `id`, then `name` among the scene's nodes; a weight on joint −1 (the
//! bind shape) and a vertex without weights follow the controller's node, `G(node) · BSM · v`.
//!
//! **Animation.** A channel targets `node-id/sid` (a whole element: 16 values for a matrix, 3 for a translation,
//! 4 for a rotation) or one member (`.X`, `.Y`, `.Z`, `.ANGLE`, or `(i)` / `(r)(c)` of a matrix); its sampler's
//! keys are interpolated linearly between key times (`STEP` keys hold; Bézier and Hermite tangents are not used)
//! and held outside them. The takes are the `<animation_clip>`s (their `start`–`end`, the channels of the
//! animations they instance), else one take `all` with every channel over its key times; a take whose keys all
//! fall on one time is no motion and is not listed. Frames are sampled at the key step when every key time of
//! the take lies on one grid of 10–120 frames per second, else at 30 per second. `<up_axis>` `Z_UP` and `X_UP`
//! are turned to Y-up. Nothing is allocated from a count the file states (`count` attributes are checked against
//! the values that follow).

use std::collections::HashMap;
use std::path::Path;

use roxmltree::Node;

use super::skeletal::{
    self, IDENTITY, Influences, Mat, ReadOptions, SkinStats, TakeInfo, clean_influences, mul, skin_frame,
};
use crate::clip::Clip;
use crate::error::{DataError, Result};

mod anim;
mod geometry;

use anim::Take;

/// Largest `.dae` file read, in bytes.
pub const MAX_DAE_BYTES: u64 = 512 << 20;

/// Deepest node nesting read.
pub const MAX_DEPTH: usize = 256;

/// Deepest element nesting of a `.dae` accepted before it is parsed: the XML parser and the readers after it
/// recurse per level, and a file nested thousands deep would overflow the stack.
pub const MAX_XML_DEPTH: usize = 512;

/// Most attributes on one element of a `.dae` accepted before it is parsed: the XML parser checks each new
/// attribute against those before it (quadratic work), and COLLADA's elements carry a handful.
pub const MAX_XML_ATTRIBUTES: usize = 256;

/// Frame rate of takes whose keys do not lie on one grid.
pub const DEFAULT_FPS: f64 = 30.0;

/// One transform element of a node.
#[derive(Clone)]
struct Element<'a> {
    sid: Option<&'a str>,
    kind: Kind,
    values: Vec<f64>,
}

#[derive(Clone, Copy, PartialEq, Eq)]
enum Kind {
    Matrix,
    Translate,
    Rotate,
    Scale,
}

impl Element<'_> {
    fn matrix(&self, v: &[f64]) -> Mat {
        match self.kind {
            Kind::Matrix => geometry::matrix(v),
            Kind::Translate => {
                let mut m = IDENTITY;
                (0..3).for_each(|k| m[k][3] = v[k]);
                m
            }
            Kind::Scale => {
                let mut m = IDENTITY;
                (0..3).for_each(|k| m[k][k] = v[k]);
                m
            }
            Kind::Rotate => {
                let n = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
                if n < 1e-12 {
                    return IDENTITY;
                }
                let (s, c) = (v[3].to_radians() / 2.0).sin_cos();
                skeletal::trs([0.0; 3], [v[0] / n * s, v[1] / n * s, v[2] / n * s, c], [1.0; 3])
            }
        }
    }
}

/// A scene node: its names, parent and transform elements.
struct SceneNode<'a> {
    id: Option<&'a str>,
    sid: Option<&'a str>,
    name: Option<&'a str>,
    parent: Option<usize>,
    elements: Vec<Element<'a>>,
}

/// The parsed file: every element with an `id`, the scene's nodes (parents first) and its instances.
pub(crate) struct Doc<'a, 'input> {
    path: &'a Path,
    ids: HashMap<&'a str, Node<'a, 'input>>,
    nodes: Vec<SceneNode<'a>>,
    /// `(node index, instance_geometry or instance_controller element)`.
    instances: Vec<(usize, Node<'a, 'input>)>,
    root: Node<'a, 'input>,
}

impl<'a, 'input> Doc<'a, 'input> {
    fn err(&self, field: impl Into<String>, reason: impl Into<String>) -> DataError {
        DataError::new(self.path, field, reason)
    }

    /// The element a `#id` URL names.
    fn url(&self, node: Node<'a, 'input>, attr: &str) -> Result<Node<'a, 'input>> {
        let field = || format!("<{} {attr}>", node.tag_name().name());
        let url = node.attribute(attr).ok_or_else(|| self.err(field(), "missing"))?;
        let id = url.strip_prefix('#').unwrap_or(url);
        self.ids
            .get(id)
            .copied()
            .ok_or_else(|| self.err(field(), format!("{url:?} names nothing in the file")))
    }

    /// Whitespace-separated numbers of `node`'s text, each finite.
    fn numbers(&self, node: Node) -> Result<Vec<f64>> {
        node.text()
            .unwrap_or_default()
            .split_whitespace()
            .map(|t| {
                t.parse::<f64>().ok().filter(|v| v.is_finite()).ok_or_else(|| {
                    self.err(
                        format!("<{}>", node.tag_name().name()),
                        format!("{t:?} is not a finite number"),
                    )
                })
            })
            .collect()
    }

    /// The values of a `<source>` (its `float_array`, or the words of its `Name_array` / `IDREF_array`) and its
    /// accessor's stride, the array's `count` checked against what it holds.
    fn source(&self, src: Node<'a, 'input>) -> Result<(Vec<f64>, Vec<&'a str>, usize)> {
        let field = || format!("<source id={:?}>", src.attribute("id").unwrap_or_default());
        let mut floats = Vec::new();
        let mut words = Vec::new();
        for a in src.children().filter(Node::is_element) {
            let held = match a.tag_name().name() {
                "float_array" => {
                    floats = self.numbers(a)?;
                    floats.len()
                }
                "Name_array" | "IDREF_array" => {
                    words = a.text().unwrap_or_default().split_whitespace().collect();
                    words.len()
                }
                _ => continue,
            };
            if let Some(c) = a.attribute("count")
                && c.parse::<usize>().ok() != Some(held)
            {
                return Err(self.err(field(), format!("count {c:?} but {held} values")));
            }
        }
        let stride = src
            .descendants()
            .find(|n| n.tag_name().name() == "accessor")
            .and_then(|a| a.attribute("stride"))
            .map_or(Ok(1), |s| {
                s.parse::<usize>()
                    .ok()
                    .filter(|s| (1..=64).contains(s))
                    .ok_or_else(|| self.err(field(), format!("accessor stride {s:?}")))
            })?;
        Ok((floats, words, stride))
    }
}

/// The first child element of `node` called `name`.
fn child<'a, 'input>(node: Node<'a, 'input>, name: &str) -> Option<Node<'a, 'input>> {
    node.children().find(|c| c.is_element() && c.tag_name().name() == name)
}

fn children<'a, 'input: 'a>(node: Node<'a, 'input>, name: &'a str) -> impl Iterator<Item = Node<'a, 'input>> + 'a {
    node.children()
        .filter(move |c| c.is_element() && c.tag_name().name() == name)
}

fn parse_doc<'a, 'input>(path: &'a Path, xml: &'a roxmltree::Document<'input>) -> Result<Doc<'a, 'input>> {
    let root = xml.root_element();
    if root.tag_name().name() != "COLLADA" {
        return Err(DataError::new(
            path,
            "root",
            format!("<{}>, not a COLLADA file", root.tag_name().name()),
        ));
    }
    let ids = xml
        .descendants()
        .filter_map(|n| n.attribute("id").map(|id| (id, n)))
        .collect();
    let mut doc = Doc {
        path,
        ids,
        nodes: Vec::new(),
        instances: Vec::new(),
        root,
    };
    let scene = match child(root, "scene").and_then(|s| child(s, "instance_visual_scene")) {
        Some(i) => doc.url(i, "url")?,
        None => root
            .descendants()
            .find(|n| n.tag_name().name() == "visual_scene")
            .ok_or_else(|| doc.err("visual_scene", "the file has no scene"))?,
    };
    for n in children(scene, "node") {
        walk(&mut doc, n, None, 0)?;
    }
    Ok(doc)
}

fn walk<'a, 'input>(
    doc: &mut Doc<'a, 'input>,
    node: Node<'a, 'input>,
    parent: Option<usize>,
    depth: usize,
) -> Result<()> {
    if depth > MAX_DEPTH {
        return Err(doc.err("node", format!("nodes nested more than {MAX_DEPTH} deep")));
    }
    if doc.nodes.len() >= skeletal::MAX_JOINTS {
        return Err(doc.err("node", format!("more than {} nodes", skeletal::MAX_JOINTS)));
    }
    let me = doc.nodes.len();
    let mut elements = Vec::new();
    for e in node.children().filter(Node::is_element) {
        let (kind, n) = match e.tag_name().name() {
            "matrix" => (Kind::Matrix, 16),
            "translate" => (Kind::Translate, 3),
            "rotate" => (Kind::Rotate, 4),
            "scale" => (Kind::Scale, 3),
            "lookat" | "skew" => {
                return Err(doc.err(
                    format!("<{}>", e.tag_name().name()),
                    "this transform element is not read",
                ));
            }
            _ => continue,
        };
        let values = doc.numbers(e)?;
        if values.len() != n {
            return Err(doc.err(
                format!("<{}>", e.tag_name().name()),
                format!("{} values (expected {n})", values.len()),
            ));
        }
        elements.push(Element {
            sid: e.attribute("sid"),
            kind,
            values,
        });
    }
    doc.nodes.push(SceneNode {
        id: node.attribute("id"),
        sid: node.attribute("sid"),
        name: node.attribute("name"),
        parent,
        elements,
    });
    for c in node.children().filter(Node::is_element) {
        match c.tag_name().name() {
            "node" => walk(doc, c, Some(me), depth + 1)?,
            "instance_geometry" | "instance_controller" => doc.instances.push((me, c)),
            _ => {}
        }
    }
    Ok(())
}

/// The `up_axis` turn to Y-up (`Z_UP` and `X_UP` are both rotations, so windings stay).
fn up_axis(doc: &Doc) -> fn([f64; 3]) -> [f64; 3] {
    let up = child(doc.root, "asset")
        .and_then(|a| child(a, "up_axis"))
        .and_then(|u| u.text())
        .unwrap_or("Y_UP")
        .trim();
    match up {
        "Z_UP" => skeletal::z_up_to_y_up,
        "X_UP" => |p: [f64; 3]| [-p[1], p[0], p[2]],
        _ => |p| p,
    }
}

fn read_xml(path: &Path) -> Result<String> {
    let bytes = super::read_file(path, MAX_DAE_BYTES.min(crate::limits::FILE_BYTES.get()))?;
    Ok(String::from_utf8_lossy(&bytes).into_owned())
}

/// The shape of an XML text as [`xml_shape`] scans it.
#[derive(Debug, PartialEq)]
struct XmlShape {
    /// Deepest element nesting.
    depth: usize,
    /// Most attributes (`=` signs outside quotes) on one element start.
    attributes: usize,
}

/// The deepest element nesting and the most attributes on one element of XML `text`, scanning tags only
/// (comments, CDATA, declarations and processing instructions skipped, quoted attribute values honoured),
/// stopping as soon as either passes its limit ([`MAX_XML_DEPTH`], [`MAX_XML_ATTRIBUTES`]). An approximate count
/// on malformed XML is harmless: the parser then refuses the file.
fn xml_shape(text: &str) -> XmlShape {
    let b = text.as_bytes();
    let find = |from: usize, pat: &[u8]| {
        b[from.min(b.len())..]
            .windows(pat.len())
            .position(|w| w == pat)
            .map_or(b.len(), |k| from + k + pat.len())
    };
    let (mut i, mut depth) = (0, 0usize);
    let mut shape = XmlShape {
        depth: 0,
        attributes: 0,
    };
    while let Some(k) = b[i..].iter().position(|&c| c == b'<') {
        i += k + 1;
        match b.get(i) {
            Some(b'/') => {
                depth = depth.saturating_sub(1);
                i = find(i, b">");
            }
            Some(b'?') => i = find(i, b"?>"),
            Some(b'!') if b[i..].starts_with(b"!--") => i = find(i, b"-->"),
            Some(b'!') if b[i..].starts_with(b"![CDATA[") => i = find(i, b"]]>"),
            Some(b'!') => i = find(i, b">"),
            Some(_) => {
                // An element start: to its closing `>` outside quotes; `/>` closes it at once.
                let mut quote = None;
                let (mut prev, mut attributes) = (0u8, 0);
                while let Some(&c) = b.get(i) {
                    match (quote, c) {
                        (None, b'"' | b'\'') => quote = Some(c),
                        (Some(q), _) if c == q => quote = None,
                        (None, b'=') => attributes += 1,
                        (None, b'>') => break,
                        _ => {}
                    }
                    prev = c;
                    i += 1;
                }
                shape.attributes = shape.attributes.max(attributes);
                if prev != b'/' {
                    depth += 1;
                    shape.depth = shape.depth.max(depth);
                }
                if shape.depth > MAX_XML_DEPTH || shape.attributes > MAX_XML_ATTRIBUTES {
                    return shape;
                }
            }
            None => break,
        }
    }
    shape
}

fn xml_doc<'i>(path: &Path, text: &'i str) -> Result<roxmltree::Document<'i>> {
    let shape = xml_shape(text);
    if shape.depth > MAX_XML_DEPTH {
        return Err(DataError::new(
            path,
            "xml",
            format!("elements nested more than {MAX_XML_DEPTH} deep"),
        ));
    }
    if shape.attributes > MAX_XML_ATTRIBUTES {
        return Err(DataError::new(
            path,
            "xml",
            format!("an element with more than {MAX_XML_ATTRIBUTES} attributes"),
        ));
    }
    let opts = roxmltree::ParsingOptions {
        allow_dtd: false,
        ..Default::default()
    };
    roxmltree::Document::parse_with_options(text, opts)
        .map_err(|e| DataError::new(path, "xml", format!("not well-formed XML: {e}")))
}

/// The takes of a `.dae` file: its animation clips (else `all`) that move something.
pub fn list_takes(path: &Path) -> Result<Vec<TakeInfo>> {
    let text = read_xml(path)?;
    let xml = xml_doc(path, &text)?;
    let doc = parse_doc(path, &xml)?;
    Ok(anim::takes(&doc)?.into_iter().map(|t| t.info).collect())
}

/// The animation clips of a `.dae` file whose keys all fall on one time (poses, not takes), by name.
pub fn one_frame_takes(path: &Path) -> Result<Vec<String>> {
    let text = read_xml(path)?;
    let xml = xml_doc(path, &text)?;
    anim::poses(&parse_doc(path, &xml)?)
}

/// Bake take `opts.take` of a `.dae` file into a clip (id = file stem, caption empty).
pub fn read(path: &Path, opts: &ReadOptions) -> Result<(Clip, SkinStats, TakeInfo)> {
    let text = read_xml(path)?;
    let xml = xml_doc(path, &text)?;
    let doc = parse_doc(path, &xml)?;
    let meshes = geometry::meshes(&doc)?;
    if meshes.iter().all(|m| m.positions.is_empty()) {
        return Err(doc.err("geometry", "no mesh in the scene"));
    }
    let takes = anim::takes(&doc)?;
    let list: Vec<TakeInfo> = takes.iter().map(|t| t.info.clone()).collect();
    let take: &Take = &takes[skeletal::pick(path, &list, &opts.take)?];
    let info = take.info.clone();
    skeletal::check_frames(path, &info.name, info.frames, opts.max_frames)?;

    // Skin slots: one per scene node (rigid vertices and joint −1 follow the instance's node), then one per
    // (mesh, joint) pair with its inverse bind matrix; a skin's bind positions are `BSM · v`.
    let n_nodes = doc.nodes.len();
    let mut bind = Vec::new();
    let mut infl: Influences = Vec::new();
    let mut faces = Vec::new();
    let mut slots: Vec<(usize, Mat)> = Vec::new();
    for m in &meshes {
        let base = bind.len() as u32;
        let first_slot = n_nodes + slots.len();
        slots.extend(m.joints.iter().copied());
        let mut lists: Influences = vec![Vec::new(); m.positions.len()];
        for (v, list) in m.weights.iter().enumerate() {
            for &(j, w) in list {
                lists[v].push((j.map_or(m.node, |j| first_slot + j), w));
            }
        }
        for l in &mut lists {
            if l.iter().all(|&(_, w)| w == 0.0) {
                *l = vec![(m.node, 1.0)];
            }
        }
        bind.extend(m.positions.iter().map(|p| skeletal::apply(&m.bind_shape, *p)));
        infl.extend(lists);
        faces.extend(m.faces.iter().map(|f| f.map(|i| i + base)));
    }
    let stats = clean_influences(path, "vertex_weights", &mut infl, n_nodes + slots.len())?;
    let parents: Vec<Option<usize>> = doc.nodes.iter().map(|n| n.parent).collect();
    let turn = up_axis(&doc);

    skeletal::check_rows(path, info.frames, bind.len())?;
    let mut vertices = Vec::with_capacity(info.frames * bind.len());
    let mut skin = Vec::with_capacity(n_nodes + slots.len());
    for f in 0..info.frames {
        let t = take.start + f as f64 / f64::from(info.fps);
        let locals: Vec<Mat> = doc
            .nodes
            .iter()
            .enumerate()
            .map(|(i, node)| anim::local(node, take.channels.get(&i).map(Vec::as_slice).unwrap_or_default(), t))
            .collect();
        let g = skeletal::globals(&parents, &locals);
        skin.clear();
        skin.extend_from_slice(&g);
        skin.extend(slots.iter().map(|(j, m)| mul(&g[*j], m)));
        skin_frame(&bind, &infl, &skin, &mut vertices);
    }
    for v in &mut vertices {
        *v = turn(v.map(f64::from)).map(|x| x as f32);
    }
    let clip = skeletal::baked_clip(path, vertices, info.frames, faces)?;
    Ok((clip, stats, info))
}

/// Text of a `.dae` for tests and `bench data`: one mesh (`positions`, triangles `faces`) skinned with vertex `v`
/// fully on root joint `j<skin[v]>` (bind matrices the identity), and one channel per joint on its `translate`
/// putting it at `keys[f][j]` at time `f / 30` s.
#[doc(hidden)]
pub fn write_test_dae(positions: &[[f32; 3]], faces: &[[u32; 3]], skin: &[u8], keys: &[Vec<[f32; 3]>]) -> String {
    use std::fmt::Write as _;
    let joints = keys.first().map_or(0, Vec::len);
    let list = |v: &mut dyn Iterator<Item = String>| v.collect::<Vec<_>>().join(" ");
    let source = |id: &str, kind: &str, values: String, count: usize, stride: usize| {
        format!(
            "<source id=\"{id}\"><{kind} id=\"{id}-a\" count=\"{}\">{values}</{kind}><technique_common>\
             <accessor source=\"#{id}-a\" count=\"{count}\" stride=\"{stride}\"/></technique_common></source>",
            count * stride
        )
    };
    let id16 = "1 0 0 0 0 1 0 0 0 0 1 0 0 0 0 1";
    let mut s = String::from(
        "<?xml version=\"1.0\"?>\n<COLLADA xmlns=\"http://www.collada.org/2005/11/COLLADASchema\" \
         version=\"1.4.1\"><asset><up_axis>Y_UP</up_axis></asset>\n<library_geometries><geometry id=\"g\"><mesh>",
    );
    s += &source(
        "p",
        "float_array",
        list(&mut positions.iter().flatten().map(f32::to_string)),
        positions.len(),
        3,
    );
    let _ = write!(
        s,
        "<vertices id=\"v\"><input semantic=\"POSITION\" source=\"#p\"/></vertices><triangles count=\"{}\">\
         <input semantic=\"VERTEX\" source=\"#v\" offset=\"0\"/><p>{}</p></triangles></mesh></geometry>\
         </library_geometries>\n<library_controllers><controller id=\"c\"><skin source=\"#g\">\
         <bind_shape_matrix>{id16}</bind_shape_matrix>",
        faces.len(),
        list(&mut faces.iter().flatten().map(u32::to_string))
    );
    s += &source(
        "jn",
        "Name_array",
        list(&mut (0..joints).map(|j| format!("j{j}"))),
        joints,
        1,
    );
    s += &source("ib", "float_array", vec![id16; joints].join(" "), joints, 16);
    s += &source("w", "float_array", "1".into(), 1, 1);
    let _ = write!(
        s,
        "<joints><input semantic=\"JOINT\" source=\"#jn\"/><input semantic=\"INV_BIND_MATRIX\" source=\"#ib\"/>\
         </joints><vertex_weights count=\"{n}\"><input semantic=\"JOINT\" source=\"#jn\" offset=\"0\"/>\
         <input semantic=\"WEIGHT\" source=\"#w\" offset=\"1\"/><vcount>{}</vcount><v>{}</v></vertex_weights>\
         </skin></controller></library_controllers>\n<library_animations>",
        vec!["1"; positions.len()].join(" "),
        list(&mut skin.iter().map(|j| format!("{j} 0"))),
        n = positions.len(),
    );
    for j in 0..joints {
        let times = list(&mut (0..keys.len()).map(|f| (f as f64 / 30.0).to_string()));
        let values = list(&mut keys.iter().flat_map(|k| k[j]).map(|x| x.to_string()));
        let _ = write!(
            s,
            "<animation id=\"a{j}\">{}{}<sampler id=\"s{j}\"><input semantic=\"INPUT\" source=\"#t{j}\"/>\
             <input semantic=\"OUTPUT\" source=\"#o{j}\"/></sampler><channel source=\"#s{j}\" target=\"j{j}/t\"/>\
             </animation>",
            source(&format!("t{j}"), "float_array", times, keys.len(), 1),
            source(&format!("o{j}"), "float_array", values, keys.len(), 3),
        );
    }
    s += "</library_animations>\n<library_visual_scenes><visual_scene id=\"s\">";
    for j in 0..joints {
        let _ = write!(
            s,
            "<node id=\"j{j}\" sid=\"j{j}\" type=\"JOINT\"><translate sid=\"t\">0 0 0</translate></node>"
        );
    }
    s += "<node id=\"m\"><instance_controller url=\"#c\"/></node></visual_scene></library_visual_scenes>\
          <scene><instance_visual_scene url=\"#s\"/></scene></COLLADA>\n";
    s
}

#[cfg(test)]
mod tests;
