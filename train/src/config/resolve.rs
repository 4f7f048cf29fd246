//! From config files to one TOML table: `extends = "tiny.toml"` chains (relative to the file, cycles refused) are
//! deep-merged base first, then `--set section.key=value` overrides are applied, then the strict parse of
//! [`from_table`] rejects any unknown or missing key with its dotted path. An ablation is thus a short overlay or a
//! command line, never a copied preset.

use std::collections::HashSet;
use std::path::{Path, PathBuf};
use std::str::FromStr;

use serde::de::DeserializeOwned;

use crate::error::{Result, TrainError};

/// The key that names a base config.
pub const EXTENDS: &str = "extends";

/// Longest `extends` chain (a guard against runaway chains; cycles are refused by name before).
pub const MAX_EXTENDS_DEPTH: usize = 16;

/// Where config files are read from: the file system, or texts embedded in the binary.
pub trait ConfigSource {
    /// The text of `path`.
    fn read(&self, path: &Path) -> std::io::Result<String>;
}

/// Config files on disk.
pub struct Files;

impl ConfigSource for Files {
    fn read(&self, path: &Path) -> std::io::Result<String> {
        std::fs::read_to_string(path)
    }
}

/// Config texts compiled into the binary, by repository path (`configs/rf/tiny.toml`), so that `extends` chains
/// resolve without the repository at hand.
pub struct Embedded(pub &'static [(&'static str, &'static str)]);

impl ConfigSource for Embedded {
    fn read(&self, path: &Path) -> std::io::Result<String> {
        let wanted = normalise(path);
        self.0
            .iter()
            .find(|(name, _)| normalise(Path::new(name)) == wanted)
            .map(|(_, text)| (*text).to_string())
            .ok_or_else(|| std::io::Error::new(std::io::ErrorKind::NotFound, "not embedded in this binary"))
    }
}

/// `a/b/../c.toml` → `a/c.toml` (without touching the file system).
fn normalise(path: &Path) -> PathBuf {
    let mut out = PathBuf::new();
    for part in path.components() {
        match part {
            std::path::Component::ParentDir => {
                out.pop();
            }
            std::path::Component::CurDir => {}
            other => out.push(other),
        }
    }
    out
}

/// One `--set section.key=value`: a dotted key path and a TOML value (`0.5`, `"cosmap"`, `{ steps = 10 }`); a
/// value that is not TOML is taken as a string, so `--set rf.tau_sampler=cosmap` works unquoted.
#[derive(Debug, Clone, PartialEq)]
pub struct Override {
    /// The key path, e.g. `["rf", "tau_sampler"]`.
    pub path: Vec<String>,
    /// The value.
    pub value: toml::Value,
}

impl FromStr for Override {
    type Err = String;

    fn from_str(text: &str) -> std::result::Result<Self, String> {
        let (key, value) = text
            .split_once('=')
            .ok_or_else(|| format!("--set {text}: expected section.key=value"))?;
        let path: Vec<String> = key.trim().split('.').map(|k| k.trim().to_string()).collect();
        if path.len() < 2 || path.iter().any(String::is_empty) {
            return Err(format!("--set {text}: the key must be section.key (e.g. rf.k_max)"));
        }
        let value = value.trim();
        let value = match toml::from_str::<toml::Table>(&format!("v = {value}")) {
            Ok(mut t) => t.remove("v").unwrap_or_else(|| toml::Value::String(value.to_string())),
            Err(_) => toml::Value::String(value.to_string()),
        };
        Ok(Override { path, value })
    }
}

impl std::fmt::Display for Override {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}={}", self.path.join("."), self.value)
    }
}

fn config_err(path: &Path, reason: String) -> TrainError {
    TrainError::Config {
        path: path.to_path_buf(),
        reason,
    }
}

/// Reads `path` from `source`, follows its `extends` chain and merges it (base first), then applies `overrides`.
/// Every error names the file (or `--set`) and the reason.
pub fn resolve(source: &dyn ConfigSource, path: &Path, overrides: &[Override]) -> Result<toml::Table> {
    let mut table = resolve_chain(source, path, &mut Vec::new())?;
    for o in overrides {
        apply(&mut table, o).map_err(|reason| config_err(path, reason))?;
    }
    Ok(table)
}

/// Parses `text` (the contents of `path`) and follows its `extends` chain through `source`.
pub fn resolve_text(source: &dyn ConfigSource, text: &str, path: &Path) -> Result<toml::Table> {
    let parsed = parse(text, path)?;
    extend(source, parsed, path, &mut vec![normalise(path)])
}

/// A parsed file and the dotted keys whose values are inline tables (`duration = { steps = 10 }`), which replace
/// the base's value instead of merging into it.
struct Parsed {
    table: toml::Table,
    inline: HashSet<String>,
}

fn parse(text: &str, path: &Path) -> Result<Parsed> {
    let table = toml::from_str(text).map_err(|e| config_err(path, format!("invalid TOML: {e}")))?;
    let doc: toml_edit::DocumentMut = text
        .parse()
        .map_err(|e| config_err(path, format!("invalid TOML: {e}")))?;
    let mut inline = HashSet::new();
    collect_inline(doc.as_table(), "", &mut inline);
    Ok(Parsed { table, inline })
}

fn collect_inline(table: &toml_edit::Table, prefix: &str, out: &mut HashSet<String>) {
    for (key, item) in table.iter() {
        let path = format!("{prefix}{key}");
        match item {
            toml_edit::Item::Table(t) => collect_inline(t, &format!("{path}."), out),
            toml_edit::Item::Value(toml_edit::Value::InlineTable(_)) => {
                out.insert(path);
            }
            _ => {}
        }
    }
}

fn resolve_chain(source: &dyn ConfigSource, path: &Path, chain: &mut Vec<PathBuf>) -> Result<toml::Table> {
    let key = normalise(path);
    if chain.contains(&key) {
        let cycle: Vec<String> = chain.iter().chain([&key]).map(|p| p.display().to_string()).collect();
        return Err(config_err(
            path,
            format!("`extends` forms a cycle: {}", cycle.join(" → ")),
        ));
    }
    if chain.len() >= MAX_EXTENDS_DEPTH {
        return Err(config_err(
            path,
            format!("`extends` chain is deeper than {MAX_EXTENDS_DEPTH} files"),
        ));
    }
    let text = source
        .read(path)
        .map_err(|e| config_err(path, format!("cannot read: {e}")))?;
    chain.push(key);
    let parsed = parse(&text, path)?;
    extend(source, parsed, path, chain)
}

/// Merges the table of `path` over its base, if it names one.
fn extend(source: &dyn ConfigSource, parsed: Parsed, path: &Path, chain: &mut Vec<PathBuf>) -> Result<toml::Table> {
    let Parsed { mut table, inline } = parsed;
    let Some(base) = table.remove(EXTENDS) else {
        return Ok(table);
    };
    let toml::Value::String(base) = base else {
        return Err(config_err(path, format!("`{EXTENDS}` must be a file name, got {base}")));
    };
    let base_path = path.parent().unwrap_or(Path::new("")).join(&base);
    let mut merged =
        resolve_chain(source, &base_path, chain).map_err(|e| config_err(path, format!("extends = \"{base}\": {e}")))?;
    deep_merge(&mut merged, table, &inline, "");
    Ok(merged)
}

/// Merges `over` into `base`: `[section]` tables merge key by key; any other value replaces the base's, inline
/// tables (dotted keys in `inline`, under `prefix`) included, so `duration = { steps = 10 }` replaces
/// `duration = { epochs = 200 }` rather than adding a second variant to it.
fn deep_merge(base: &mut toml::Table, over: toml::Table, inline: &HashSet<String>, prefix: &str) {
    for (key, value) in over {
        let path = format!("{prefix}{key}");
        match (base.get_mut(&key), value) {
            (Some(toml::Value::Table(b)), toml::Value::Table(o)) if !inline.contains(&path) => {
                deep_merge(b, o, inline, &format!("{path}."))
            }
            (_, value) => {
                base.insert(key, value);
            }
        }
    }
}

/// Sets one override; the key must already exist (the same check as an unknown key in a file).
fn apply(table: &mut toml::Table, o: &Override) -> std::result::Result<(), String> {
    let Some((last, parents)) = o.path.split_last() else {
        return Err(format!("--set {o}: no key"));
    };
    let mut here = table;
    for (depth, key) in parents.iter().enumerate() {
        here = match here.get_mut(key) {
            Some(toml::Value::Table(t)) => t,
            _ => return Err(format!("--set {o}: unknown key `{}`", o.path[..=depth].join("."))),
        };
    }
    match here.get_mut(last) {
        Some(slot) => {
            *slot = o.value.clone();
            Ok(())
        }
        None => Err(format!("--set {o}: unknown key `{}`", o.path.join("."))),
    }
}

/// The strict parse: `C` (whose structs deny unknown fields) from a resolved table; an unknown, missing or
/// mistyped key is an error naming its dotted path and `path`.
pub fn from_table<C: DeserializeOwned>(table: toml::Table, path: &Path) -> Result<C> {
    serde_path_to_error::deserialize(toml::Value::Table(table)).map_err(|e| {
        let at = e.path().to_string();
        let reason = if at == "." || at.is_empty() {
            e.inner().to_string()
        } else {
            format!("{at}: {}", e.inner())
        };
        config_err(path, reason)
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    const BASE: &str = "[a]\nx = 1\ny = \"keep\"\n[a.inner]\nz = 2.0\n[b]\nw = [1, 2]\n";

    fn files(list: &'static [(&'static str, &'static str)]) -> Embedded {
        Embedded(list)
    }

    #[test]
    fn an_inline_table_replaces_the_base_value_instead_of_merging() {
        let src = files(&[
            (
                "base.toml",
                "[train]\nduration = { epochs = 200 }\nseed = 1\n[optim]\nschedule = \"constant\"\n",
            ),
            (
                "over.toml",
                "extends = \"base.toml\"\n[train]\nduration = { steps = 10 }\n[optim.schedule.warmup_cosine]\nwarmup_steps = 2\n",
            ),
        ]);
        let t = resolve(&src, Path::new("over.toml"), &[]).unwrap();
        let duration = t["train"]["duration"].as_table().unwrap();
        assert_eq!(duration.keys().collect::<Vec<_>>(), ["steps"], "{duration:?}");
        assert_eq!(t["train"]["seed"].as_integer(), Some(1), "the rest of [train] merges");
        assert_eq!(
            t["optim"]["schedule"]["warmup_cosine"]["warmup_steps"].as_integer(),
            Some(2)
        );
    }

    #[test]
    fn extends_merges_tables_deeply_and_relative_to_the_file() {
        let src = files(&[
            ("c/base.toml", BASE),
            (
                "c/sub/over.toml",
                "extends = \"../base.toml\"\n[a]\nx = 5\n[a.inner]\nz = 3.0\n",
            ),
            ("c/sub/twice.toml", "extends = \"over.toml\"\n[b]\nw = [7]\n"),
        ]);
        let t = resolve(&src, Path::new("c/sub/twice.toml"), &[]).unwrap();
        assert_eq!(t["a"]["x"].as_integer(), Some(5));
        assert_eq!(t["a"]["y"].as_str(), Some("keep"));
        assert_eq!(t["a"]["inner"]["z"].as_float(), Some(3.0));
        assert_eq!(t["b"]["w"].as_array().map(Vec::len), Some(1));
        assert!(!t.contains_key(EXTENDS));
    }

    #[test]
    fn cycles_and_missing_bases_are_refused_by_name() {
        let src = files(&[
            ("a.toml", "extends = \"b.toml\"\n"),
            ("b.toml", "extends = \"./a.toml\"\n"),
            ("c.toml", "extends = \"gone.toml\"\n"),
            ("d.toml", "extends = 3\n"),
        ]);
        let err = resolve(&src, Path::new("a.toml"), &[]).unwrap_err().to_string();
        assert!(
            err.contains("cycle") && err.contains("a.toml → b.toml → a.toml"),
            "{err}"
        );
        let err = resolve(&src, Path::new("c.toml"), &[]).unwrap_err().to_string();
        assert!(
            err.contains("c.toml") && err.contains("gone.toml") && err.contains("cannot read"),
            "{err}"
        );
        let err = resolve(&src, Path::new("d.toml"), &[]).unwrap_err().to_string();
        assert!(err.contains("must be a file name"), "{err}");
    }

    #[test]
    fn overrides_parse_as_toml_and_must_name_existing_keys() {
        let src = files(&[("base.toml", BASE)]);
        let sets: Vec<Override> = ["a.x=7", "a.inner.z = 0.5", "a.y=plain", "b.w=[3, 4, 5]"]
            .iter()
            .map(|s| s.parse().unwrap())
            .collect();
        let t = resolve(&src, Path::new("base.toml"), &sets).unwrap();
        assert_eq!(t["a"]["x"].as_integer(), Some(7));
        assert_eq!(t["a"]["inner"]["z"].as_float(), Some(0.5));
        assert_eq!(t["a"]["y"].as_str(), Some("plain"));
        assert_eq!(t["b"]["w"].as_array().map(Vec::len), Some(3));
        for (bad, needle) in [("a.nope=1", "unknown key `a.nope`"), ("c.x=1", "unknown key `c`")] {
            let err = resolve(&src, Path::new("base.toml"), &[bad.parse().unwrap()])
                .unwrap_err()
                .to_string();
            assert!(err.contains(needle) && err.contains("base.toml"), "{bad}: {err}");
        }
        assert!("x=1".parse::<Override>().unwrap_err().contains("section.key"));
        assert!("a.x".parse::<Override>().unwrap_err().contains("section.key=value"));
    }

    #[test]
    fn the_strict_parse_names_the_dotted_path() {
        #[derive(Debug, serde::Deserialize)]
        #[serde(deny_unknown_fields)]
        #[allow(dead_code)]
        struct Inner {
            z: f64,
        }
        #[derive(Debug, serde::Deserialize)]
        #[serde(deny_unknown_fields)]
        #[allow(dead_code)]
        struct A {
            x: i64,
            y: String,
            inner: Inner,
        }
        #[derive(Debug, serde::Deserialize)]
        #[serde(deny_unknown_fields)]
        #[allow(dead_code)]
        struct Top {
            a: A,
            b: toml::Value,
        }
        let ok: toml::Table = toml::from_str(BASE).unwrap();
        assert!(from_table::<Top>(ok, Path::new("t.toml")).is_ok());
        let extra: toml::Table = toml::from_str(&BASE.replace("z = 2.0", "z = 2.0\nq = 1")).unwrap();
        let err = from_table::<Top>(extra, Path::new("t.toml")).unwrap_err().to_string();
        assert!(
            err.contains("t.toml") && err.contains("a.inner") && err.contains("`q`"),
            "{err}"
        );
        let missing: toml::Table = toml::from_str(&BASE.replace("x = 1\n", "")).unwrap();
        let err = from_table::<Top>(missing, Path::new("t.toml")).unwrap_err().to_string();
        assert!(err.contains("missing field `x`"), "{err}");
    }
}
