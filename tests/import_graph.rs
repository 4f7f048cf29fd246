//! The module import graph of each crate, read from its source: which file names which through `crate::`,
//! `super::` and `self::` paths, and the circles in it (files that reach each other by such paths). A circle is a
//! set of modules that cannot be understood or moved one at a time; the known ones are listed below with the
//! crate, so a new circle, or a known one that grows, fails the test, and a circle that has been broken must leave
//! the list. `cargo test --test import_graph -- --nocapture` prints every crate's count.
//!
//! Edges are paths in code and doc links outside `#[cfg(test)] mod tests` blocks and `//` comments; a parent's
//! `mod child;` and its plain `child::` paths are not edges (a module owns its children), so a circle is always
//! made of at least one path that climbs (`super::`, or `crate::` to an ancestor's sibling) and one that comes back.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

/// The crates whose graphs are checked: (name, source folder).
const CRATES: &[(&str, &str)] = &[
    ("any4d", "src"),
    ("formats", "formats/src"),
    ("data", "data/src"),
    ("model", "model/src"),
    ("eval", "eval/src"),
    ("train", "train/src"),
];

/// The circles there are today, by crate, each as its files' module paths (`""` is the crate root). The list only
/// shrinks: breaking a circle means deleting its entry.
const KNOWN_CIRCLES: &[(&str, &[&str])] = &[("model", &["any_vae", "dymesh_vae", "frame_vae", "mesh_vae"])];

fn root() -> &'static Path {
    Path::new(env!("CARGO_MANIFEST_DIR"))
}

/// Every `.rs` file below `dir`.
fn rust_files(dir: &Path) -> Vec<PathBuf> {
    let mut out = Vec::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for entry in std::fs::read_dir(&d)
            .unwrap_or_else(|e| panic!("{}: {e}", d.display()))
            .flatten()
        {
            let path = entry.path();
            if path.is_dir() {
                stack.push(path);
            } else if path.extension().is_some_and(|e| e == "rs") {
                out.push(path);
            }
        }
    }
    out.sort();
    out
}

/// The module path of a file below a crate's source folder: `lib.rs`/`main.rs` → [], `a/mod.rs` → [a],
/// `a/b.rs` → [a, b].
fn module_of(relative: &Path) -> Vec<String> {
    let mut parts: Vec<String> = relative
        .with_extension("")
        .components()
        .map(|c| c.as_os_str().to_string_lossy().into_owned())
        .collect();
    if matches!(parts.last().map(String::as_str), Some("mod" | "lib" | "main")) {
        parts.pop();
    }
    parts
}

/// The file's code without its test module and `//` comments (doc comments are kept: their links are edges).
fn code_of(text: &str) -> String {
    let body = match text.find("#[cfg(test)]\nmod tests") {
        Some(i) => &text[..i],
        None => text,
    };
    body.lines()
        .map(|line| {
            let trimmed = line.trim_start();
            if trimmed.starts_with("//") && !trimmed.starts_with("///") && !trimmed.starts_with("//!") {
                ""
            } else {
                line
            }
        })
        .collect::<Vec<_>>()
        .join("\n")
}

/// Tokens that matter to paths: identifiers, `::`, braces and commas; anything else is a separator.
#[derive(Debug, Clone, PartialEq)]
enum Token {
    Ident(String),
    Sep,
    Open,
    Close,
    Comma,
    Other,
}

fn tokens(code: &str) -> Vec<Token> {
    let chars: Vec<char> = code.chars().collect();
    let mut out = Vec::new();
    let mut i = 0;
    while i < chars.len() {
        let c = chars[i];
        if c.is_alphanumeric() || c == '_' {
            let start = i;
            while i < chars.len() && (chars[i].is_alphanumeric() || chars[i] == '_') {
                i += 1;
            }
            out.push(Token::Ident(chars[start..i].iter().collect()));
            continue;
        }
        out.push(match c {
            ':' if chars.get(i + 1) == Some(&':') => {
                i += 1;
                Token::Sep
            }
            '{' => Token::Open,
            '}' => Token::Close,
            ',' => Token::Comma,
            c if c.is_whitespace() => {
                i += 1;
                continue;
            }
            _ => Token::Other,
        });
        i += 1;
    }
    out
}

/// Reads a path tree after `base` from `toks[*at]` (just past a `::`): `a::b`, `a::{b, c::d}`, `{a, b}`; pushes
/// every leaf path (base + segments) to `out`.
fn path_tree(toks: &[Token], at: &mut usize, base: Vec<String>, out: &mut Vec<Vec<String>>) {
    let mut path = base;
    loop {
        match toks.get(*at) {
            Some(Token::Ident(name)) => {
                *at += 1;
                match name.as_str() {
                    "super" => {
                        path.pop();
                    }
                    "self" => {}
                    _ => path.push(name.clone()),
                }
                if toks.get(*at) == Some(&Token::Sep) {
                    *at += 1;
                    continue;
                }
                out.push(path);
                return;
            }
            Some(Token::Open) => {
                *at += 1;
                loop {
                    path_tree(toks, at, path.clone(), out);
                    match toks.get(*at) {
                        Some(Token::Comma) => *at += 1,
                        Some(Token::Close) => {
                            *at += 1;
                            return;
                        }
                        _ => return,
                    }
                    if toks.get(*at) == Some(&Token::Close) {
                        *at += 1;
                        return;
                    }
                }
            }
            _ => {
                out.push(path);
                return;
            }
        }
    }
}

/// Every module path a file's code names through `crate::`, `super::` or `self::`, resolved from `module`
/// (a `mod.rs` or a leaf file alike: `super` is the parent of the file's module).
fn named_paths(code: &str, module: &[String]) -> Vec<Vec<String>> {
    let toks = tokens(code);
    let mut out = Vec::new();
    let mut i = 0;
    while i + 1 < toks.len() {
        let start = match &toks[i] {
            Token::Ident(w) if toks[i + 1] == Token::Sep => match w.as_str() {
                "crate" => Some(Vec::new()),
                "super" => Some(module[..module.len().saturating_sub(1)].to_vec()),
                "self" => Some(module.to_vec()),
                _ => None,
            },
            _ => None,
        };
        // Part of a longer path (`a::super::b` does not occur; `x::crate` cannot): only a path's first word counts.
        let first = i == 0 || toks[i - 1] != Token::Sep;
        match start {
            Some(base) if first => {
                let mut at = i + 2;
                path_tree(&toks, &mut at, base, &mut out);
                i = at;
            }
            _ => i += 1,
        }
    }
    out
}

/// The crate's graph: for each file's module, the modules (files) it names.
fn graph(src: &Path) -> BTreeMap<Vec<String>, BTreeSet<Vec<String>>> {
    let files = rust_files(src);
    let modules: BTreeSet<Vec<String>> = files.iter().map(|f| module_of(f.strip_prefix(src).unwrap())).collect();
    let mut edges = BTreeMap::new();
    for file in &files {
        let module = module_of(file.strip_prefix(src).unwrap());
        let code = code_of(&std::fs::read_to_string(file).unwrap());
        let mut to = BTreeSet::new();
        for path in named_paths(&code, &module) {
            // The file that holds what the path names: its longest prefix that is a module.
            let target = (0..=path.len())
                .rev()
                .map(|k| path[..k].to_vec())
                .find(|p| modules.contains(p))
                .unwrap_or_default();
            if target != module {
                to.insert(target);
            }
        }
        edges.insert(module, to);
    }
    edges
}

/// The strongly connected components of more than one module (Tarjan's algorithm, iteration over a sorted graph,
/// so the output is deterministic).
fn circles(edges: &BTreeMap<Vec<String>, BTreeSet<Vec<String>>>) -> Vec<Vec<String>> {
    struct State<'a> {
        edges: &'a BTreeMap<Vec<String>, BTreeSet<Vec<String>>>,
        index: BTreeMap<&'a Vec<String>, usize>,
        low: BTreeMap<&'a Vec<String>, usize>,
        stack: Vec<&'a Vec<String>>,
        on_stack: BTreeSet<&'a Vec<String>>,
        out: Vec<Vec<String>>,
    }
    fn visit<'a>(s: &mut State<'a>, v: &'a Vec<String>) {
        let n = s.index.len();
        s.index.insert(v, n);
        s.low.insert(v, n);
        s.stack.push(v);
        s.on_stack.insert(v);
        let edges = s.edges;
        for w in edges.get(v).into_iter().flatten() {
            if !s.index.contains_key(w) {
                visit(s, w);
                let lw = s.low[w];
                let lv = s.low.get_mut(v).unwrap();
                *lv = (*lv).min(lw);
            } else if s.on_stack.contains(w) {
                let iw = s.index[w];
                let lv = s.low.get_mut(v).unwrap();
                *lv = (*lv).min(iw);
            }
        }
        if s.low[v] == s.index[v] {
            let mut component = Vec::new();
            while let Some(w) = s.stack.pop() {
                s.on_stack.remove(w);
                component.push(w.join("::"));
                if w == v {
                    break;
                }
            }
            if component.len() > 1 {
                component.sort();
                s.out.push(component);
            }
        }
    }
    let mut s = State {
        edges,
        index: BTreeMap::new(),
        low: BTreeMap::new(),
        stack: Vec::new(),
        on_stack: BTreeSet::new(),
        out: Vec::new(),
    };
    for v in edges.keys() {
        if !s.index.contains_key(v) {
            visit(&mut s, v);
        }
    }
    s.out.sort();
    s.out
}

#[test]
fn the_only_import_circles_are_the_known_ones() {
    let mut found = BTreeSet::new();
    for &(name, src) in CRATES {
        let edges = graph(&root().join(src));
        let crate_circles = circles(&edges);
        let files: usize = crate_circles.iter().map(Vec::len).sum();
        println!(
            "{name}: {} files, {} edges, {} circles over {files} files",
            edges.len(),
            edges.values().map(BTreeSet::len).sum::<usize>(),
            crate_circles.len()
        );
        for c in crate_circles {
            println!("  {}", c.join(" ↔ "));
            found.insert((name.to_string(), c));
        }
    }
    let known: BTreeSet<(String, Vec<String>)> = KNOWN_CIRCLES
        .iter()
        .map(|(name, files)| (name.to_string(), files.iter().map(|f| f.to_string()).collect()))
        .collect();
    let new: Vec<_> = found.difference(&known).collect();
    let gone: Vec<_> = known.difference(&found).collect();
    assert!(
        new.is_empty() && gone.is_empty(),
        "import circles changed.\nnew (break them, or list them with the reason): {new:?}\n\
         no longer there (delete them from KNOWN_CIRCLES): {gone:?}"
    );
}

#[test]
fn the_reader_of_paths_finds_what_it_looks_for() {
    let module = vec!["a".to_string(), "b".to_string()];
    let code = "use crate::x::{y, z::{w, self}};\nuse super::{c, super::d};\nfn f() { self::e::g(); crate::h(); }\n\
                /// [`crate::i::j`]\nlet s = foo::crate_thing;";
    let paths: BTreeSet<String> = named_paths(code, &module).iter().map(|p| p.join("::")).collect();
    let expected: BTreeSet<String> = ["x::y", "x::z::w", "x::z", "a::c", "d", "a::b::e::g", "h", "i::j"]
        .iter()
        .map(|s| s.to_string())
        .collect();
    assert_eq!(paths, expected);
    assert_eq!(module_of(Path::new("a/mod.rs")), vec!["a"]);
    assert_eq!(module_of(Path::new("a/b.rs")), vec!["a", "b"]);
    assert!(module_of(Path::new("lib.rs")).is_empty());
    let code = code_of("use crate::a;\n// crate::b\n#[cfg(test)]\nmod tests {\n use crate::c;\n}\n");
    assert_eq!(named_paths(&code, &module), vec![vec!["a".to_string()]]);
    let edge = |from: &str, to: &[&str]| {
        (
            from.split("::").map(String::from).collect::<Vec<_>>(),
            to.iter()
                .map(|t| t.split("::").map(String::from).collect())
                .collect::<BTreeSet<Vec<String>>>(),
        )
    };
    let g: BTreeMap<_, _> = [
        edge("p", &["q"]),
        edge("q", &["r"]),
        edge("r", &["p"]),
        edge("s", &["p"]),
    ]
    .into();
    assert_eq!(circles(&g), vec![vec!["p".to_string(), "q".into(), "r".into()]]);
}
