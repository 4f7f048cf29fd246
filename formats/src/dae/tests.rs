//! The COLLADA reader on written files: skinning, transform elements and members, clips, and broken input.

use super::*;

const TRI: [[f32; 3]; 3] = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.5]];

fn skinned() -> String {
    let keys = vec![vec![[0.0; 3], [0.0; 3]], vec![[0.0; 3], [0.5, 0.25, 0.0]]];
    write_test_dae(&TRI, &[[0, 1, 2]], &[0, 1, 1], &keys)
}

fn bake_opts(text: &str, opts: &ReadOptions) -> Result<(Clip, SkinStats, TakeInfo)> {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("thing.dae");
    std::fs::write(&path, text).unwrap();
    read(&path, opts)
}

fn bake(text: &str) -> Result<(Clip, SkinStats, TakeInfo)> {
    bake_opts(text, &ReadOptions::default())
}

fn close(a: [f32; 3], b: [f32; 3]) -> bool {
    a.iter().zip(b).all(|(x, y)| (x - y).abs() < 1e-5)
}

/// A triangle on node `n` (`<translate sid="t">` then `<rotate sid="r">` about z), with `channels` (`<animation>`
/// elements) and `extra` elements after the scene library.
fn rigid(channels: &str, extra: &str, up: &str) -> String {
    format!(
        r##"<?xml version="1.0"?>
<COLLADA xmlns="http://www.collada.org/2005/11/COLLADASchema" version="1.4.1">
 <asset><up_axis>{up}</up_axis></asset>
 <library_geometries><geometry id="g"><mesh>
  <source id="p"><float_array id="pa" count="9">0 0 0 1 0 0 0 1 0</float_array>
   <technique_common><accessor source="#pa" count="3" stride="3"/></technique_common></source>
  <vertices id="v"><input semantic="POSITION" source="#p"/></vertices>
  <polylist count="1"><input semantic="VERTEX" source="#v" offset="0"/><input semantic="NORMAL" source="#p" offset="1"/>
   <vcount>3</vcount><p>0 0 1 1 2 2</p></polylist>
 </mesh></geometry></library_geometries>
 <library_animations>{channels}</library_animations>
 {extra}
 <library_visual_scenes><visual_scene id="s">
  <node id="n"><translate sid="t">0 0 0</translate><rotate sid="r">0 0 1 0</rotate>
   <instance_geometry url="#g"/></node>
 </visual_scene></library_visual_scenes>
 <scene><instance_visual_scene url="#s"/></scene>
</COLLADA>"##
    )
}

/// An `<animation>` with keys `times` → `values` (`stride` values per key) on `target`.
fn anim(id: &str, target: &str, times: &[f64], values: &[f64], stride: usize, interp: Option<&str>) -> String {
    let join = |v: &[f64]| v.iter().map(f64::to_string).collect::<Vec<_>>().join(" ");
    let n = times.len();
    let interp_src = interp.map_or(String::new(), |i| {
        format!(
            r##"<source id="{id}-i"><Name_array id="{id}-ia" count="{n}">{}</Name_array>
             <technique_common><accessor source="#{id}-ia" count="{n}" stride="1"/></technique_common></source>"##,
            vec![i; n].join(" ")
        )
    });
    let interp_in = interp.map_or(String::new(), |_| {
        format!(r##"<input semantic="INTERPOLATION" source="#{id}-i"/>"##)
    });
    format!(
        r##"<animation id="{id}">
  <source id="{id}-t"><float_array id="{id}-ta" count="{n}">{}</float_array>
   <technique_common><accessor source="#{id}-ta" count="{n}" stride="1"/></technique_common></source>
  <source id="{id}-o"><float_array id="{id}-oa" count="{}">{}</float_array>
   <technique_common><accessor source="#{id}-oa" count="{n}" stride="{stride}"/></technique_common></source>
  {interp_src}
  <sampler id="{id}-s"><input semantic="INPUT" source="#{id}-t"/><input semantic="OUTPUT" source="#{id}-o"/>{interp_in}</sampler>
  <channel source="#{id}-s" target="{target}"/>
 </animation>"##,
        join(times),
        values.len(),
        join(values),
    )
}

#[test]
fn the_test_writer_round_trips_with_skinning() {
    let (clip, stats, info) = bake(&skinned()).unwrap();
    assert_eq!(
        (info.name.as_str(), info.frames, info.fps, stats.vertices),
        ("all", 2, 30.0, 3)
    );
    assert_eq!(clip.faces, vec![[0, 1, 2]]);
    assert_eq!(clip.frame(0), &TRI);
    assert_eq!(clip.frame(1), &[[0.0, 0.0, 0.0], [1.5, 0.25, 0.0], [0.5, 1.25, 0.5]]);
}

#[test]
fn members_clips_and_step_keys() {
    // The angle member turns 0° → 90° over 1 s (keys off any 10-120 fps grid: sampled at 30 fps), the
    // translation's X member steps to 2 at 0.5 s.
    let channels = anim("a", "n/r.ANGLE", &[0.0, 1.0], &[0.0, 90.0], 1, None)
        + &anim("b", "n/t.X", &[0.0, 0.5], &[0.0, 2.0], 1, Some("STEP"));
    let (clip, _, info) = bake(&rigid(&channels, "", "Y_UP")).unwrap();
    assert_eq!((info.frames, info.fps), (31, 30.0));
    let s = 0.5f32.sqrt();
    assert!(close(clip.frame(15)[1], [2.0 + s, s, 0.0]), "{:?}", clip.frame(15));
    assert!(close(clip.frame(30)[1], [2.0, 1.0, 0.0]), "{:?}", clip.frame(30));
    // STEP holds 0 until the key at 0.5 s.
    assert!(close(clip.frame(14)[0], [0.0, 0.0, 0.0]), "{:?}", clip.frame(14));
    assert!(close(clip.frame(15)[0], [2.0, 0.0, 0.0]), "{:?}", clip.frame(15));
    // Two clips: `turn` instances the rotation only, over its first half; `still` has no moving key.
    let clips = r##"<library_animation_clips>
        <animation_clip name="turn" start="0" end="0.5"><instance_animation url="#a"/></animation_clip>
        <animation_clip name="still"/></library_animation_clips>"##;
    let text = rigid(&channels, clips, "Y_UP");
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("c.dae");
    std::fs::write(&path, &text).unwrap();
    let takes = list_takes(&path).unwrap();
    assert_eq!((takes.len(), takes[0].name.as_str(), takes[0].frames), (1, "turn", 16));
    let (clip, _, _) = read(&path, &ReadOptions::default()).unwrap();
    assert!(close(clip.frame(15)[1], [s, s, 0.0]), "{:?}", clip.frame(15));
    // `still` has no key at all: neither a take nor a pose. A clip whose keys all sit at one time is a pose.
    assert!(one_frame_takes(&path).unwrap().is_empty());
    let pose = anim("c", "n/t.Y", &[0.25], &[1.0], 1, None);
    let clips = r##"<library_animation_clips>
        <animation_clip name="turn"><instance_animation url="#a"/></animation_clip>
        <animation_clip name="aim"><instance_animation url="#c"/></animation_clip></library_animation_clips>"##;
    std::fs::write(&path, rigid(&(channels + &pose), clips, "Y_UP")).unwrap();
    assert_eq!(list_takes(&path).unwrap().len(), 1);
    assert_eq!(one_frame_takes(&path).unwrap(), ["aim"]);
}

#[test]
fn whole_elements_matrices_and_the_up_axis() {
    // A whole-translate channel, keys on a 24 fps grid; a Z-up file turned Y-up.
    let t = anim(
        "a",
        "n/t",
        &[0.0, 1.0 / 24.0, 2.0 / 24.0],
        &[0., 0., 0., 0., 0., 1., 0., 0., 2.],
        3,
        None,
    );
    let (clip, _, info) = bake(&rigid(&t, "", "Z_UP")).unwrap();
    assert_eq!((info.frames, info.fps), (3, 24.0));
    assert!(close(clip.frame(2)[2], [0.0, 2.0, -1.0]), "{:?}", clip.frame(2));
    // A matrix element animated whole (row-major, translation in the last column) and by one member.
    let keys = anim("m", "n/x", &[0.0, 0.1, 0.2, 0.3], &[0.0, 1.0, 2.0, 3.0], 1, None);
    let text = rigid(&keys, "", "Y_UP")
        .replace(
            r#"<rotate sid="r">0 0 1 0</rotate>"#,
            r#"<matrix sid="x">1 0 0 0 0 1 0 0 0 0 1 0 0 0 0 1</matrix>"#,
        )
        .replace("n/x", "n/x(1)(3)");
    let (clip, _, _) = bake(&text).unwrap();
    assert!(close(clip.frame(3)[0], [0.0, 3.0, 0.0]), "{:?}", clip.frame(3));
}

#[test]
fn broken_files_get_reasons() {
    let cases: Vec<(String, &str)> = vec![
        (
            skinned().replace("count=\"9\"", "count=\"10\""),
            "count \"10\" but 9 values",
        ),
        (skinned().replace("<p>0 1 2</p>", "<p>0 1 7</p>"), "vertex 7 of 3"),
        (
            skinned().replace("<v>0 0 1 0 1 0</v>", "<v>0 0 1 0 5 0</v>"),
            "names joint 5 of 2",
        ),
        (
            skinned().replace("<v>0 0 1 0 1 0</v>", "<v>0 0 1 0</v>"),
            "<v> ends inside vertex 2",
        ),
        (
            skinned().replace("<vcount>1 1 1</vcount>", "<vcount>1 1</vcount>"),
            "weights for 2 vertices",
        ),
        (skinned().replace(">j0 j1<", ">j0 jX<"), "joint \"jX\" is not a node"),
        (
            skinned().replace("<bind_shape_matrix>1 0 0 0", "<bind_shape_matrix>1 0 0"),
            "bind_shape_matrix has 15",
        ),
        (skinned().replace(">0 0.03333333333333333<", ">0 -1<"), "go back"),
        (
            skinned().replace(">0 0.03333333333333333<", ">0 nan<"),
            "not a finite number",
        ),
        (
            skinned()
                .replace("<COLLADA", "<COLLADAX")
                .replace("</COLLADA>", "</COLLADAX>"),
            "not a COLLADA file",
        ),
        (skinned()[..skinned().len() / 2].to_string(), "not well-formed XML"),
        (
            "<?xml version=\"1.0\"?><!DOCTYPE x [<!ENTITY a \"aaaa\">]><COLLADA/>".to_string(),
            "not well-formed XML",
        ),
        (rigid("", "", "Y_UP"), "static mesh is not a clip"),
    ];
    for (text, reason) in cases {
        let e = bake(&text).unwrap_err();
        assert!(e.reason.contains(reason), "{reason}: {e}");
    }
    // Nodes nested past the limit.
    let deep = "<node>".repeat(MAX_DEPTH + 2) + &"</node>".repeat(MAX_DEPTH + 2);
    let text = rigid("", "", "Y_UP").replace("<node id=\"n\">", &format!("{deep}<node id=\"n\">"));
    assert!(bake(&text).unwrap_err().reason.contains("nested"));
    // Any element nested past the XML limit is refused before parsing (20,000 levels overflowed the stack).
    for tag in ["animation", "extra", "node"] {
        let deep = format!("<{tag}>").repeat(20_000) + &format!("</{tag}>").repeat(20_000);
        let text = rigid("", "", "Y_UP").replace("<library_visual_scenes>", &format!("{deep}<library_visual_scenes>"));
        let e = bake(&text).unwrap_err();
        assert!(e.reason.contains("elements nested more than"), "{tag}: {e}");
    }
    // Just under the limit the file parses on a thread of Rust's default 2 MiB stack (an overflow would abort
    // the test process) and is refused for what it lacks, the motion.
    let deep = "<extra>".repeat(MAX_XML_DEPTH - 8) + &"</extra>".repeat(MAX_XML_DEPTH - 8);
    let text = rigid("", "", "Y_UP").replace("<library_visual_scenes>", &format!("{deep}<library_visual_scenes>"));
    let parsed = std::thread::Builder::new()
        .stack_size(2 << 20)
        .spawn(move || bake(&text).map(|_| ()))
        .unwrap()
        .join()
        .unwrap();
    assert!(parsed.unwrap_err().reason.contains("static mesh"));
    // Comments, CDATA, quoted `>` and self-closed elements do not count as nesting.
    let flat = "<a x=\"1>2\"/><!-- <b><b><b> --><![CDATA[<c><c>]]><?pi <d>?>".repeat(MAX_XML_DEPTH);
    let shape = xml_shape(&format!("<r>{flat}<e><f/></e></r>"));
    assert_eq!(
        shape,
        XmlShape {
            depth: 2,
            attributes: 1
        }
    );
    // An element with 128k attributes (the parser's duplicate check is quadratic in them) is refused unparsed;
    // `=` inside quoted values is not an attribute.
    let many: String = (0..131_072).map(|k| format!(" a{k}=\"{k}\"")).collect();
    let text = rigid("", "", "Y_UP").replace(
        "<library_visual_scenes>",
        &format!("<extra{many}/><library_visual_scenes>"),
    );
    let e = bake(&text).unwrap_err();
    assert!(e.reason.contains("more than 256 attributes"), "{e}");
    assert_eq!(xml_shape("<a b=\"x=y=z\" c='=' d=\"1\"/>").attributes, 3);
    // A take longer than the frame limit is refused before it is baked.
    let opts = ReadOptions {
        max_frames: 1,
        ..ReadOptions::default()
    };
    assert!(
        bake_opts(&skinned(), &opts)
            .unwrap_err()
            .reason
            .contains("maximum of 1")
    );
}
