//! Small text helpers shared by the KITTI parsers: read a file, split a line into numbers,
//! with errors that name the file and the 1-based line.

use std::path::{Path, PathBuf};

use super::DatasetError;

/// Reads a whole text file (a missing file is `MissingFile`).
pub(crate) fn read_text(path: &Path) -> Result<String, DatasetError> {
    std::fs::read_to_string(path).map_err(|e| DatasetError::io(path, &e))
}

/// Parses every whitespace-separated token of `s` as a finite `f64`.
///
/// With `expected = Some(n)` the line must hold exactly `n` numbers. Tokens are checked left to
/// right, and the count before the values, so a short line reports `BadFieldCount` even when it
/// also holds a NaN.
pub(crate) fn parse_numbers(
    path: &Path,
    line: usize,
    s: &str,
    expected: Option<usize>,
) -> Result<Vec<f64>, DatasetError> {
    let tokens: Vec<&str> = s.split_whitespace().collect();
    if let Some(n) = expected {
        if tokens.len() != n {
            return Err(DatasetError::BadFieldCount {
                path: path.to_path_buf(),
                line,
                expected: n,
                got: tokens.len(),
            });
        }
    }
    tokens.iter().map(|t| parse_f64(path, line, t)).collect()
}

/// Parses one token as a finite `f64`.
pub(crate) fn parse_f64(path: &Path, line: usize, token: &str) -> Result<f64, DatasetError> {
    let v: f64 = token.parse().map_err(|_| DatasetError::Parse {
        path: path.to_path_buf(),
        line,
        msg: format!("`{token}` is not a number"),
    })?;
    if v.is_finite() {
        Ok(v)
    } else {
        Err(DatasetError::NonFinite { path: path.to_path_buf(), line })
    }
}

/// Non-blank lines of `text` with their 1-based line numbers; `#` starts a comment (a whole
/// line or the rest of one), as in evo's and many users' KITTI pose files.
pub(crate) fn numbered_lines(text: &str) -> impl Iterator<Item = (usize, &str)> {
    text.lines()
        .enumerate()
        .map(|(i, l)| (i + 1, l.split('#').next().unwrap_or("").trim()))
        .filter(|(_, l)| !l.is_empty())
}

/// A file of lines holding `n` numbers each (KITTI pose files: `n = 12`; `times.txt`: `n = 1`).
pub(crate) fn read_rows(path: &Path, n: usize) -> Result<Vec<Vec<f64>>, DatasetError> {
    let text = read_text(path)?;
    numbered_lines(&text).map(|(line, l)| parse_numbers(path, line, l, Some(n))).collect()
}

/// Like [`read_rows`], but a bad line ends the rows instead of failing: the rows before it
/// and the error. For ground truth, where the frames before a problem are still usable.
pub(crate) fn read_rows_prefix(
    path: &Path,
    n: usize,
) -> Result<(Vec<Vec<f64>>, Option<DatasetError>), DatasetError> {
    let text = read_text(path)?;
    let mut rows = Vec::new();
    for (line, l) in numbered_lines(&text) {
        match parse_numbers(path, line, l, Some(n)) {
            Ok(r) => rows.push(r),
            Err(e) => return Ok((rows, Some(e))),
        }
    }
    Ok((rows, None))
}

/// The files in `dir` whose extension is `ext` (case-insensitive), sorted by file name.
///
/// KITTI names frames with zero-padded numbers, so name order is frame order.
pub(crate) fn list_files(dir: &Path, ext: &str) -> Result<Vec<PathBuf>, DatasetError> {
    let entries = std::fs::read_dir(dir).map_err(|e| DatasetError::io(dir, &e))?;
    let mut files = Vec::new();
    for entry in entries {
        let entry = entry.map_err(|e| DatasetError::io(dir, &e))?;
        let path = entry.path();
        let matches =
            path.extension().and_then(|x| x.to_str()).is_some_and(|x| x.eq_ignore_ascii_case(ext));
        if matches && path.is_file() {
            files.push(path);
        }
    }
    files.sort();
    Ok(files)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn p() -> PathBuf {
        PathBuf::from("f.txt")
    }

    #[test]
    fn parses_scientific_and_plain_numbers() {
        let v = parse_numbers(&p(), 3, " 1e-05 -2.5\t7 ", None).unwrap();
        assert_eq!(v, vec![1e-5, -2.5, 7.0]);
    }

    #[test]
    fn count_is_checked() {
        let e = parse_numbers(&p(), 4, "1 2 3", Some(4)).unwrap_err();
        assert_eq!(e, DatasetError::BadFieldCount { path: p(), line: 4, expected: 4, got: 3 });
    }

    #[test]
    fn nan_inf_and_garbage_are_rejected() {
        for bad in ["nan", "NaN", "inf", "-inf"] {
            let e = parse_numbers(&p(), 2, &format!("1 {bad}"), None).unwrap_err();
            assert_eq!(e, DatasetError::NonFinite { path: p(), line: 2 });
        }
        let e = parse_numbers(&p(), 9, "1 x2", None).unwrap_err();
        assert!(matches!(e, DatasetError::Parse { line: 9, .. }), "{e}");
        assert!(e.to_string().contains("f.txt:9"), "{e}");
    }

    #[test]
    fn blank_lines_are_skipped_but_numbering_kept() {
        let v: Vec<_> = numbered_lines("a\n\n  \r\nb\r\n").collect();
        assert_eq!(v, vec![(1, "a"), (4, "b")]);
        let v: Vec<_> = numbered_lines("# header\n1 2 # note\n  # x\n3").collect();
        assert_eq!(v, vec![(2, "1 2"), (4, "3")]);
    }
}
