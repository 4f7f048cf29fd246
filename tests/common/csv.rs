//! A committed CSV of an experiment, read for the pages generated from them (tests/readme_results.rs,
//! tests/results_page.rs): header and rows of strings, a value looked up by key columns.

use std::path::Path;

/// A committed CSV: header and rows of strings (the files cited hold no quoted fields; a row with a different number
/// of cells than the header, as a quoted comma would make, is refused).
pub struct Csv {
    pub path: String,
    pub header: Vec<String>,
    pub rows: Vec<Vec<String>>,
}

impl Csv {
    pub fn read(path: &str) -> Csv {
        let text = std::fs::read_to_string(Path::new(env!("CARGO_MANIFEST_DIR")).join(path))
            .unwrap_or_else(|e| panic!("{path}: {e}"));
        Csv::parse(path, &text)
    }

    pub fn parse(path: &str, text: &str) -> Csv {
        let mut lines = text.lines().filter(|l| !l.trim().is_empty());
        let split = |l: &str| l.split(',').map(String::from).collect::<Vec<_>>();
        let header = split(lines.next().unwrap_or_else(|| panic!("{path}: empty")));
        let rows: Vec<Vec<String>> = lines.map(split).collect();
        for row in &rows {
            assert_eq!(row.len(), header.len(), "{path}: a row of {} cells: {row:?}", row.len());
        }
        Csv {
            path: path.to_string(),
            header,
            rows,
        }
    }

    /// The value of `column` in the one row whose columns `key` equal the given values.
    pub fn get(&self, key: &[(&str, &str)], column: &str) -> f64 {
        let col = |name: &str| {
            self.header
                .iter()
                .position(|h| h == name)
                .unwrap_or_else(|| panic!("{}: no column {name}", self.path))
        };
        let matching: Vec<&Vec<String>> = self
            .rows
            .iter()
            .filter(|r| key.iter().all(|(k, v)| r[col(k)] == *v))
            .collect();
        assert_eq!(
            matching.len(),
            1,
            "{}: {} rows match {key:?}",
            self.path,
            matching.len()
        );
        let cell = &matching[0][col(column)];
        cell.parse()
            .unwrap_or_else(|e| panic!("{}: {column} = {cell:?}: {e}", self.path))
    }
}
