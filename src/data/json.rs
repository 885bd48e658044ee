//! Typed access to JSON files with errors that name the file, the field and what was expected.

use std::path::Path;

use serde_json::{Map, Value};

use super::{DataError, DataResult};

/// Reads and parses a JSON file.
pub(crate) fn read(path: &Path) -> DataResult<Value> {
    let bytes = std::fs::read(path).map_err(|e| DataError::io(path, e))?;
    serde_json::from_slice(&bytes).map_err(|e| DataError::Json {
        path: path.display().to_string(),
        msg: e.to_string(),
    })
}

/// Describes a JSON value for an error message ("a string \"abc\"", "an array of 2 elements").
pub(crate) fn describe(v: &Value) -> String {
    match v {
        Value::Null => "null".into(),
        Value::Bool(b) => format!("a boolean ({b})"),
        Value::Number(n) => format!("the number {n}"),
        Value::String(s) => {
            let short: String = s.chars().take(40).collect();
            format!("a string \"{short}\"")
        }
        Value::Array(a) => format!("an array of {} elements", a.len()),
        Value::Object(o) => format!("an object with {} fields", o.len()),
    }
}

pub(crate) fn field_err(
    path: &Path,
    field: &str,
    expected: impl Into<String>,
    found: impl Into<String>,
) -> DataError {
    DataError::Field {
        path: path.display().to_string(),
        field: field.to_string(),
        expected: expected.into(),
        found: found.into(),
    }
}

/// A JSON object inside a file, with the dotted path of fields leading to it.
#[derive(Clone, Copy)]
pub(crate) struct Obj<'a> {
    pub path: &'a Path,
    prefix: &'a str,
    map: &'a Map<String, Value>,
}

impl<'a> Obj<'a> {
    /// The top-level object of a file.
    pub fn root(path: &'a Path, v: &'a Value) -> DataResult<Obj<'a>> {
        Self::of(path, "", v, "(top level)")
    }

    /// Wraps `v`, which must be an object, named `name` for messages.
    pub fn of(path: &'a Path, prefix: &'a str, v: &'a Value, name: &str) -> DataResult<Obj<'a>> {
        match v {
            Value::Object(map) => Ok(Obj { path, prefix, map }),
            other => Err(field_err(path, name, "an object", describe(other))),
        }
    }

    pub fn name(&self, field: &str) -> String {
        if self.prefix.is_empty() {
            field.to_string()
        } else {
            format!("{}.{}", self.prefix, field)
        }
    }

    /// A field that may be absent (null counts as absent).
    pub fn opt(&self, field: &str) -> Option<&'a Value> {
        self.map.get(field).filter(|v| !v.is_null())
    }

    pub fn has(&self, field: &str) -> bool {
        self.opt(field).is_some()
    }

    pub fn req(&self, field: &str, expected: &str) -> DataResult<&'a Value> {
        self.opt(field)
            .ok_or_else(|| field_err(self.path, &self.name(field), expected, "nothing (missing)"))
    }

    pub fn f64(&self, field: &str) -> DataResult<f64> {
        let v = self.req(field, "a number")?;
        num(self.path, &self.name(field), v)
    }

    pub fn opt_f64(&self, field: &str) -> DataResult<Option<f64>> {
        match self.opt(field) {
            None => Ok(None),
            Some(v) => num(self.path, &self.name(field), v).map(Some),
        }
    }

    /// A finite number that must be > 0.
    pub fn positive(&self, field: &str) -> DataResult<f64> {
        let x = self.f64(field)?;
        if x > 0.0 {
            Ok(x)
        } else {
            Err(field_err(
                self.path,
                &self.name(field),
                "a positive number",
                format!("{x}"),
            ))
        }
    }

    pub fn str(&self, field: &str) -> DataResult<&'a str> {
        let v = self.req(field, "a string")?;
        v.as_str()
            .ok_or_else(|| field_err(self.path, &self.name(field), "a string", describe(v)))
    }

    /// An array of numbers with one of the allowed lengths.
    pub fn nums(&self, field: &str, lens: &[usize]) -> DataResult<Vec<f64>> {
        let expected = expected_nums(lens);
        let v = self.req(field, &expected)?;
        nums(self.path, &self.name(field), v, lens)
    }

    pub fn opt_nums(&self, field: &str, lens: &[usize]) -> DataResult<Option<Vec<f64>>> {
        match self.opt(field) {
            None => Ok(None),
            Some(v) => nums(self.path, &self.name(field), v, lens).map(Some),
        }
    }

    /// A `rows×cols` matrix given as an array of rows.
    pub fn matrix(&self, field: &str, rows: usize, cols: usize) -> DataResult<Vec<Vec<f64>>> {
        let expected = format!("a {rows}×{cols} array of numbers");
        let v = self.req(field, &expected)?;
        let name = self.name(field);
        let arr = match v {
            Value::Array(a) if a.len() == rows => a,
            other => return Err(field_err(self.path, &name, expected, describe(other))),
        };
        arr.iter()
            .enumerate()
            .map(|(i, row)| nums(self.path, &format!("{name}[{i}]"), row, &[cols]))
            .collect()
    }

    pub fn array(&self, field: &str) -> DataResult<&'a Vec<Value>> {
        let v = self.req(field, "an array")?;
        v.as_array()
            .ok_or_else(|| field_err(self.path, &self.name(field), "an array", describe(v)))
    }

    /// An array of strings.
    pub fn strings(&self, field: &str) -> DataResult<Vec<String>> {
        let name = self.name(field);
        self.array(field)?
            .iter()
            .enumerate()
            .map(|(i, v)| {
                v.as_str().map(str::to_string).ok_or_else(|| {
                    field_err(self.path, &format!("{name}[{i}]"), "a string", describe(v))
                })
            })
            .collect()
    }
}

fn expected_nums(lens: &[usize]) -> String {
    let l: Vec<String> = lens.iter().map(|l| l.to_string()).collect();
    format!("an array of {} numbers", l.join(" or "))
}

/// A finite number.
pub(crate) fn num(path: &Path, name: &str, v: &Value) -> DataResult<f64> {
    match v.as_f64() {
        Some(x) if x.is_finite() => Ok(x),
        _ => Err(field_err(path, name, "a finite number", describe(v))),
    }
}

/// An array of finite numbers with one of the allowed lengths.
pub(crate) fn nums(path: &Path, name: &str, v: &Value, lens: &[usize]) -> DataResult<Vec<f64>> {
    let expected = expected_nums(lens);
    let arr = match v {
        Value::Array(a) if lens.contains(&a.len()) => a,
        other => return Err(field_err(path, name, expected, describe(other))),
    };
    arr.iter()
        .enumerate()
        .map(|(i, x)| num(path, &format!("{name}[{i}]"), x))
        .collect()
}
