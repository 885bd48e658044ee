//! Metric tables as GitHub-flavoured Markdown, readable both rendered and in a terminal, and
//! parsed back so that tests and scripts can compare runs.

use serde::Serialize;

use crate::error::{Error, Result};

/// A table of text cells under one header row.
#[derive(Clone, Debug, PartialEq, Eq, Serialize)]
pub struct Table {
    pub headers: Vec<String>,
    pub rows: Vec<Vec<String>>,
}

/// Escapes a cell so it cannot end the cell early: '|' becomes "\|" and '\' becomes "\\"
/// (GitHub renders both as the plain character). Line breaks would end the table, so they
/// become spaces; that is the one change parsing cannot undo.
fn escape(cell: &str) -> String {
    let mut out = String::with_capacity(cell.len());
    for c in cell.chars() {
        match c {
            '|' => out.push_str("\\|"),
            '\\' => out.push_str("\\\\"),
            '\r' => {}
            '\n' => out.push(' '),
            c => out.push(c),
        }
    }
    out
}

/// Reverses [`escape`]: "\|" and "\\" become one character, any other backslash stays, so
/// hand-written tables with stray backslashes still read as written.
fn unescape(cell: &str) -> String {
    let mut out = String::with_capacity(cell.len());
    let mut chars = cell.chars().peekable();
    while let Some(c) = chars.next() {
        if c == '\\' {
            if let Some(&n) = chars.peek().filter(|&&n| n == '|' || n == '\\') {
                out.push(n);
                chars.next();
                continue;
            }
        }
        out.push(c);
    }
    out
}

/// Splits one table line into trimmed, unescaped cells; None when it is not a pipe row
/// (does not start with '|'). A trailing unescaped '|' closes the row rather than opening
/// an empty last cell.
fn split_row(line: &str) -> Option<Vec<String>> {
    let body = line.trim().strip_prefix('|')?;
    let mut raw: Vec<String> = Vec::new();
    let mut cur = String::new();
    let mut closed = false;
    let mut chars = body.chars();
    while let Some(c) = chars.next() {
        closed = false;
        match c {
            // Keep escapes intact here; unescape runs after trimming.
            '\\' => {
                cur.push(c);
                if let Some(n) = chars.next() {
                    cur.push(n);
                }
            }
            '|' => {
                raw.push(std::mem::take(&mut cur));
                closed = true;
            }
            c => cur.push(c),
        }
    }
    if !closed {
        raw.push(cur);
    }
    Some(raw.iter().map(|c| unescape(c.trim())).collect())
}

/// True for a separator cell such as "---", ":--", "--:" or ":-:".
fn is_separator_cell(cell: &str) -> bool {
    let inner = cell.strip_prefix(':').unwrap_or(cell);
    let inner = inner.strip_suffix(':').unwrap_or(inner);
    !inner.is_empty() && inner.chars().all(|c| c == '-')
}

impl Table {
    /// A GitHub pipe table: header, separator (first column left-aligned, the rest
    /// right-aligned, as numbers read best), one line per row, columns padded to a common
    /// width. Rows shorter than the header are padded with empty cells; a table with no
    /// columns gives an empty string.
    pub fn to_markdown(&self) -> String {
        let ncols = self
            .rows
            .iter()
            .map(Vec::len)
            .chain([self.headers.len()])
            .max()
            .unwrap_or(0);
        if ncols == 0 {
            return String::new();
        }
        let escaped = |row: &[String]| -> Vec<String> {
            (0..ncols)
                .map(|i| row.get(i).map_or(String::new(), |c| escape(c)))
                .collect()
        };
        let header = escaped(&self.headers);
        let body: Vec<Vec<String>> = self.rows.iter().map(|r| escaped(r)).collect();
        // Three dashes is the shortest separator cell GitHub accepts.
        let mut widths = vec![3usize; ncols];
        for row in std::iter::once(&header).chain(&body) {
            for (w, c) in widths.iter_mut().zip(row) {
                *w = (*w).max(c.chars().count());
            }
        }
        let line = |cells: &[String]| -> String {
            let mut s = String::from("|");
            for (i, (c, &w)) in cells.iter().zip(&widths).enumerate() {
                if i == 0 {
                    s += &format!(" {c:<w$} |");
                } else {
                    s += &format!(" {c:>w$} |");
                }
            }
            s.push('\n');
            s
        };
        let sep: Vec<String> = widths
            .iter()
            .enumerate()
            .map(|(i, &w)| {
                if i == 0 {
                    "-".repeat(w)
                } else {
                    "-".repeat(w - 1) + ":"
                }
            })
            .collect();
        let mut out = line(&header);
        out += &line(&sep);
        for row in &body {
            out += &line(row);
        }
        out
    }

    /// Reads the first pipe table in `s`: a '|' line followed by a separator line with the
    /// same number of cells; lines before it are skipped and the table ends at the first
    /// line that does not start with '|'. Every row must have as many cells as the header.
    /// Errors give 1-based line numbers.
    pub fn parse_markdown(s: &str) -> Result<Table> {
        let lines: Vec<&str> = s.lines().collect();
        for (i, pair) in lines.windows(2).enumerate() {
            let (Some(headers), Some(sep)) = (split_row(pair[0]), split_row(pair[1])) else {
                continue;
            };
            if sep.is_empty() || !sep.iter().all(|c| is_separator_cell(c)) {
                continue;
            }
            if sep.len() != headers.len() {
                return Err(Error::Invalid(format!(
                    "markdown table, line {}: separator has {} cells, the header on line {} has {}",
                    i + 2,
                    sep.len(),
                    i + 1,
                    headers.len()
                )));
            }
            let mut rows = Vec::new();
            for (j, line) in lines.iter().enumerate().skip(i + 2) {
                let Some(cells) = split_row(line) else {
                    break;
                };
                if cells.len() != headers.len() {
                    return Err(Error::Invalid(format!(
                        "markdown table, line {}: row has {} cells, the header has {}",
                        j + 1,
                        cells.len(),
                        headers.len()
                    )));
                }
                rows.push(cells);
            }
            return Ok(Table { headers, rows });
        }
        Err(Error::Invalid(
            "no markdown pipe table found (a '|' header line followed by a '|---|' separator line)"
                .into(),
        ))
    }
}

/// `v` with `decimals` places; "n/a" for None or a non-finite value. Values that round to
/// zero print without a minus sign.
pub fn fmt_metric(v: Option<f64>, decimals: usize) -> String {
    match v {
        Some(v) if v.is_finite() => {
            let s = format!("{v:.decimals$}");
            match s.strip_prefix('-') {
                Some(rest) if rest.chars().all(|c| c == '0' || c == '.') => rest.to_string(),
                _ => s,
            }
        }
        _ => "n/a".into(),
    }
}
