//! Debian machine-readable `copyright` files (DEP-5): which licence covers a packaged file.

use std::path::Path;

/// A Debian machine-readable `copyright` file: `Files:` patterns and their `License:`; the last matching
/// stanza wins.
pub struct Dep5 {
    stanzas: Vec<(Vec<String>, String)>,
}

impl Dep5 {
    /// Read `path`; a missing or unreadable file gives no stanzas (licences then read "unknown").
    pub fn read(path: &Path) -> Self {
        Self::parse(&std::fs::read_to_string(path).unwrap_or_default())
    }

    pub fn parse(text: &str) -> Self {
        let mut stanzas = Vec::new();
        for block in text.split("\n\n") {
            let mut files = Vec::new();
            let mut licence = None;
            let mut in_files = false;
            for line in block.lines() {
                if let Some(rest) = line.strip_prefix("Files:") {
                    in_files = true;
                    files.extend(rest.split_whitespace().map(str::to_owned));
                } else if line.starts_with([' ', '\t']) && in_files {
                    files.extend(line.split_whitespace().map(str::to_owned));
                } else {
                    in_files = false;
                    if let Some(rest) = line.strip_prefix("License:")
                        && licence.is_none()
                    {
                        licence = Some(rest.trim().to_owned());
                    }
                }
            }
            if let (false, Some(l)) = (files.is_empty(), licence) {
                stanzas.push((files, l));
            }
        }
        Self { stanzas }
    }

    /// The licence of `path` (an installed or archive path; a pattern may match any tail of it that starts at a
    /// folder boundary), or "unknown".
    pub fn licence(&self, path: &str) -> String {
        let tails: Vec<&str> = std::iter::once(path)
            .chain(path.match_indices('/').map(|(i, _)| &path[i + 1..]))
            .collect();
        self.stanzas
            .iter()
            .rev()
            .find(|(pats, _)| pats.iter().any(|p| tails.iter().any(|t| glob(p, t))))
            .map_or_else(|| "unknown".to_owned(), |(_, l)| l.clone())
    }
}

/// `*` matches any run of characters (also `/`), `?` one character.
fn glob(pat: &str, s: &str) -> bool {
    let (p, t): (Vec<char>, Vec<char>) = (pat.chars().collect(), s.chars().collect());
    let (mut pi, mut ti, mut star, mut mark) = (0, 0, None, 0);
    while ti < t.len() {
        if pi < p.len() && (p[pi] == '?' || p[pi] == t[ti]) {
            pi += 1;
            ti += 1;
        } else if pi < p.len() && p[pi] == '*' {
            star = Some(pi);
            mark = ti;
            pi += 1;
        } else if let Some(sp) = star {
            pi = sp + 1;
            mark += 1;
            ti = mark;
        } else {
            return false;
        }
    }
    p[pi..].iter().all(|&c| c == '*')
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn dep5_last_matching_stanza_wins() {
        let c = Dep5::parse(
            "Format: x\n\nFiles: *\nCopyright: a\nLicense: GPL-2+\n\nFiles: base/models/aliens/a.md2\n base/models/x/*\n\
             Copyright: b\nLicense: CC-BY-SA-3.0\n more text\n",
        );
        assert_eq!(c.licence("models/y/z.md2"), "GPL-2+");
        assert_eq!(c.licence("base/models/aliens/a.md2"), "CC-BY-SA-3.0");
        assert_eq!(c.licence("usr/share/games/ufoai/base/models/x/q/b.md2"), "CC-BY-SA-3.0");
        assert_eq!(Dep5::parse("").licence("a"), "unknown");
        assert!(glob("a*c?e", "abbbcde") && !glob("a*c", "abd"));
    }
}
