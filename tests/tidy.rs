//! The repository's house rules, checked by `cargo test` (after rust-analyzer's `tidy.rs`): every Rust file opens
//! with a `//!` line, files over 600 lines are on a short written allow-list, no comment or document cites an issue
//! number or a path outside the repository, every equation tag the code uses is defined in `docs/method.md`, every
//! tag defined there is named by some code, and the files that document names exist.

use std::collections::BTreeSet;
use std::path::{Path, PathBuf};

/// The longest a source file may be before it needs a written reason.
const MAX_LINES: usize = 600;

/// Files allowed past [`MAX_LINES`], each with the reason it stays whole. An entry that is no longer needed fails the
/// test, so the list only shrinks.
const LONG_FILES: &[(&str, &str)] = &[
    (
        "formats/src/bvh.rs",
        "the BVH parser and its retargeting onto a rig share one joint-name table and rest-pose alignment",
    ),
    (
        "formats/src/iqm.rs",
        "one IQM file: header, bounds-checked arrays, skin, animations and the test writer that mirrors them",
    ),
    (
        "eval/tests/learned.rs",
        "one fixture (a woken tiny VAE and RF, a byte text encoder, a waving-flag clip) serves every sampler test",
    ),
    (
        "model/src/mesh_vae.rs",
        "the body both VAEs share, its config and (V1)–(V3): one trait's building blocks",
    ),
    (
        "eval/src/metrics.rs",
        "(E1)–(E7) and their shared checks, the pure functions of one table",
    ),
    (
        "model/tests/rf.rs",
        "the flow conventions and every sampler mode, tested against one oracle set-up",
    ),
    (
        "train/tests/rf_tiny.rs",
        "one shared trained fixture serves every RF loop test; splitting retrains it",
    ),
];

fn root() -> &'static Path {
    Path::new(env!("CARGO_MANIFEST_DIR"))
}

/// Every file below the repository root with one of `extensions`, except build output, hidden folders and
/// test fixtures.
fn files(extensions: &[&str]) -> Vec<PathBuf> {
    fn walk(dir: &Path, extensions: &[&str], out: &mut Vec<PathBuf>) {
        let Ok(entries) = std::fs::read_dir(dir) else { return };
        for entry in entries.flatten() {
            let path = entry.path();
            let name = entry.file_name().to_string_lossy().into_owned();
            if path.is_dir() {
                if !(name.starts_with('.') || name == "target" || name == "fixtures" || name == "runs") {
                    walk(&path, extensions, out);
                }
            } else if extensions.iter().any(|e| name.ends_with(e)) {
                out.push(path);
            }
        }
    }
    let mut out = Vec::new();
    walk(root(), extensions, &mut out);
    out.sort();
    out
}

fn relative(path: &Path) -> String {
    path.strip_prefix(root()).unwrap_or(path).display().to_string()
}

fn read(path: &Path) -> String {
    std::fs::read_to_string(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

#[test]
fn every_rust_file_opens_with_a_module_doc_line() {
    let missing: Vec<String> = files(&[".rs"])
        .iter()
        .filter(|p| !read(p).starts_with("//!"))
        .map(|p| relative(p))
        .collect();
    assert!(missing.is_empty(), "files without a leading `//!` line: {missing:?}");
}

/// The workspace denies `unsafe` code; one function may set the CPU's floating-point modes, which safe Rust cannot
/// (model/src/denormals.rs). The lint's name appears in no other source file (no allowance, expectation or module-wide
/// allowance elsewhere), the workspace denies it, and every crate inherits the workspace's lints.
#[test]
fn the_unsafe_lint_is_allowed_for_one_function_of_the_denormals_module_only() {
    let allowed = "model/src/denormals.rs";
    let lint = ["unsafe", "_code"].concat();
    let found: Vec<String> = files(&[".rs"])
        .iter()
        .filter(|p| read(p).contains(&lint))
        .map(|p| relative(p))
        .filter(|p| p != allowed)
        .collect();
    assert!(found.is_empty(), "the unsafe lint named outside {allowed}: {found:?}");
    let module = read(&root().join(allowed));
    assert_eq!(
        module.matches(&lint).count(),
        1,
        "{allowed}: one function-level allowance"
    );
    assert!(
        module.contains(&format!("#[allow({lint})]\npub fn set_flush_denormals")),
        "{allowed}: on the function"
    );
    let workspace = read(&root().join("Cargo.toml"));
    assert!(
        workspace.contains(&format!("{lint} = \"deny\"")),
        "Cargo.toml: the workspace denies it"
    );
    for member in [
        "Cargo.toml",
        "formats/Cargo.toml",
        "data/Cargo.toml",
        "model/Cargo.toml",
        "eval/Cargo.toml",
        "train/Cargo.toml",
    ] {
        let toml = read(&root().join(member));
        assert!(
            toml.contains("[lints]\nworkspace = true"),
            "{member}: inherits the workspace lints"
        );
        assert!(
            member == "Cargo.toml" || !toml.contains(&lint),
            "{member}: no lint level of its own"
        );
    }
}

#[test]
fn long_files_are_on_the_allow_list_with_a_reason() {
    let mut too_long = Vec::new();
    let mut long = BTreeSet::new();
    for path in files(&[".rs"]) {
        let lines = read(&path).lines().count();
        let name = relative(&path);
        if lines > MAX_LINES {
            long.insert(name.clone());
            if !LONG_FILES.iter().any(|(f, _)| *f == name) {
                too_long.push(format!("{name} ({lines} lines)"));
            }
        }
    }
    assert!(
        too_long.is_empty(),
        "files over {MAX_LINES} lines: split them, or add them to LONG_FILES with a reason: {too_long:?}"
    );
    let stale: Vec<&str> = LONG_FILES
        .iter()
        .map(|(f, _)| *f)
        .filter(|f| !long.contains(*f))
        .collect();
    assert!(
        stale.is_empty(),
        "LONG_FILES entries no longer over {MAX_LINES} lines: {stale:?}"
    );
    assert!(
        LONG_FILES.iter().all(|(_, why)| why.len() > 20),
        "every entry needs a reason"
    );
}

/// What a line of `text` says outside code: the comment part of a source line, or the whole line of prose.
fn prose(path: &Path, line: &str) -> Option<String> {
    let name = path.to_string_lossy();
    if name.ends_with(".md") {
        return Some(line.to_string());
    }
    let marker = if name.ends_with(".rs") { "//" } else { "#" };
    line.find(marker).map(|i| line[i..].to_string())
}

/// The word "issue" followed by a number, or a `#` followed by one: a citation a clone cannot follow.
fn cites_an_issue(text: &str) -> bool {
    let lower = text.to_lowercase();
    let bytes = lower.as_bytes();
    let digit_at = |i: usize| bytes.get(i).is_some_and(u8::is_ascii_digit);
    lower.match_indices("issue").any(|(i, _)| {
        let after = i + "issue".len();
        matches!(bytes.get(after), Some(b' ' | b'-')) && digit_at(after + 1)
    }) || lower
        .match_indices('#')
        .any(|(i, _)| digit_at(i + 1) && (i == 0 || bytes[i - 1] == b' '))
}

#[test]
fn no_comment_or_document_cites_an_issue_or_a_path_outside_the_repository() {
    let outside = ["../shared", "SPEC §", "SPEC.md", "SPEC (", "STYLE.md", "/work/"];
    let mut bad = Vec::new();
    for path in files(&[".rs", ".toml", ".md", ".py", "run"]) {
        for (n, line) in read(&path).lines().enumerate() {
            let Some(text) = prose(&path, line) else { continue };
            if let Some(p) = outside.iter().find(|p| text.contains(**p)) {
                bad.push(format!("{}:{}: cites `{p}`", relative(&path), n + 1));
            }
            if cites_an_issue(&text) {
                bad.push(format!(
                    "{}:{}: cites an issue: {}",
                    relative(&path),
                    n + 1,
                    text.trim()
                ));
            }
        }
    }
    assert!(bad.is_empty(), "citations a clone cannot follow:\n{}", bad.join("\n"));
}

/// Every `(D1)`-style tag in `text`: a letter of D, V, R, E, H, B, L and digits in parentheses.
fn tags(text: &str) -> BTreeSet<String> {
    let mut out = BTreeSet::new();
    let b = text.as_bytes();
    for (i, _) in text.match_indices('(') {
        let Some(&letter) = b.get(i + 1) else { continue };
        if !b"DVREHBL".contains(&letter) {
            continue;
        }
        let digits = b[i + 2..].iter().take_while(|c| c.is_ascii_digit()).count();
        if digits > 0 && b.get(i + 2 + digits) == Some(&b')') {
            out.insert(text[i..i + 3 + digits].to_string());
        }
    }
    out
}

#[test]
fn every_equation_tag_in_the_code_is_defined_in_the_method_document() {
    let method = read(&root().join("docs/method.md"));
    let defined = tags(&method);
    let mut undefined = BTreeSet::new();
    for path in files(&[".rs"]) {
        for tag in tags(&read(&path)) {
            if !defined.contains(&tag) {
                undefined.insert(format!("{tag} in {}", relative(&path)));
            }
        }
    }
    assert!(defined.len() >= 27, "docs/method.md defines only {defined:?}");
    assert!(
        undefined.is_empty(),
        "tags without an equation in docs/method.md: {undefined:?}"
    );
}

#[test]
fn every_equation_tag_of_the_method_document_is_carried_by_some_code() {
    // Doc → code: an equation no line of code or test names is one nobody can find the implementation of.
    let defined = tags(&read(&root().join("docs/method.md")));
    let mut carried = BTreeSet::new();
    for path in files(&[".rs"]) {
        carried.extend(tags(&read(&path)));
    }
    let orphans: Vec<&String> = defined.difference(&carried).collect();
    assert!(
        orphans.is_empty(),
        "docs/method.md tags that no code line names: {orphans:?}"
    );
}

#[test]
fn files_named_by_the_method_document_exist() {
    let method = read(&root().join("docs/method.md"));
    let missing: Vec<&str> = method
        .split('`')
        .skip(1)
        .step_by(2)
        .filter(|s| s.ends_with(".rs") || s.ends_with(".toml") || s.ends_with('/'))
        .filter(|s| s.contains('/') && !s.contains(' ') && !s.contains('*'))
        .filter(|s| !root().join(s).exists())
        .collect();
    assert!(
        missing.is_empty(),
        "docs/method.md names files that do not exist: {missing:?}"
    );
}

#[test]
fn the_scanners_find_what_they_look_for() {
    let word = "issue";
    for cited in [
        format!("see {word} 5 item 2"),
        format!("fixed in #{}", 13),
        format!("{word}-7"),
    ] {
        assert!(cites_an_issue(&cited), "{cited}");
    }
    for fine in ["#[derive(Debug)]", "the issue is", "a#1"] {
        assert!(!cites_an_issue(fine), "{fine}");
    }
    // Built at run time, so the scan of this file does not find an undefined tag.
    let text = format!("x ({}7) and ({}12), not (X1) nor (R) nor (D1a)", 'R', 'E');
    let expected = [format!("({}12)", 'E'), format!("({}7)", 'R')];
    assert_eq!(tags(&text).into_iter().collect::<Vec<_>>(), expected);
}
