//! Tables: CSV files from serde rows, Markdown tables from rows and column specs.
//!
//! A CSV row type derives `serde::Serialize` and `serde::Deserialize`; its field names are the
//! header (also for a file without rows, through [`header`]), so the columns are declared once.
//! Floats go through [`sci`] (`with = "sci"`), the shortest round-trip form (`1.5e-3`), so
//! values read back exactly; `None` is an empty field. Methods and outcomes go through [`text`]
//! (`Display` out, `FromStr` in).
//!
//! A Markdown table is a list of [`Column`]s, each a heading and a function from a row to its
//! cell, applied to every row by [`markdown`].

use std::fs;
use std::path::Path;

use serde::de::{self, Deserializer, Visitor};
use serde::{Deserialize, Serialize};

use super::ReportError;

/// `#[serde(with = "sci")]`: a float in the shortest round-trip form, `{:e}` (`NaN` stays
/// `NaN`).
pub mod sci {
    use serde::{Deserialize, Deserializer, Serializer};

    /// Writes `{x:e}`.
    pub fn serialize<S: Serializer>(x: &f64, s: S) -> Result<S::Ok, S::Error> {
        s.collect_str(&format_args!("{x:e}"))
    }

    /// Reads any float Rust parses.
    pub fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<f64, D::Error> {
        let s = String::deserialize(d)?;
        s.parse().map_err(serde::de::Error::custom)
    }

    /// `#[serde(with = "sci::opt")]`: [`sci`](self) for an optional float; `None` is empty.
    pub mod opt {
        use serde::{Deserialize, Deserializer, Serializer};

        /// Writes `{x:e}`, or nothing.
        pub fn serialize<S: Serializer>(x: &Option<f64>, s: S) -> Result<S::Ok, S::Error> {
            match x {
                Some(x) => super::serialize(x, s),
                None => s.serialize_str(""),
            }
        }

        /// Reads a float, or `None` from an empty field.
        pub fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<Option<f64>, D::Error> {
            let s = String::deserialize(d)?;
            if s.is_empty() {
                return Ok(None);
            }
            s.parse().map(Some).map_err(serde::de::Error::custom)
        }
    }
}

/// `#[serde(with = "text")]`: a value by its `Display` form, read back with `FromStr`
/// (methods, outcomes).
pub mod text {
    use std::fmt::Display;
    use std::str::FromStr;

    use serde::{Deserialize, Deserializer, Serializer};

    /// Writes `x.to_string()`.
    pub fn serialize<T: Display, S: Serializer>(x: &T, s: S) -> Result<S::Ok, S::Error> {
        s.collect_str(x)
    }

    /// Parses the field.
    pub fn deserialize<'de, T, D>(d: D) -> Result<T, D::Error>
    where
        T: FromStr<Err: Display>,
        D: Deserializer<'de>,
    {
        let s = String::deserialize(d)?;
        s.parse().map_err(serde::de::Error::custom)
    }
}

/// A deserializer that only records the field names a struct asks for.
struct FieldNames<'a>(&'a mut &'static [&'static str]);

impl<'de> Deserializer<'de> for FieldNames<'_> {
    type Error = de::value::Error;

    fn deserialize_any<V: Visitor<'de>>(self, _: V) -> Result<V::Value, Self::Error> {
        Err(de::Error::custom("a CSV row must be a struct"))
    }

    fn deserialize_struct<V: Visitor<'de>>(
        self,
        _: &'static str,
        fields: &'static [&'static str],
        _: V,
    ) -> Result<V::Value, Self::Error> {
        *self.0 = fields;
        Err(de::Error::custom("field names only"))
    }

    serde::forward_to_deserialize_any! {
        bool i8 i16 i32 i64 i128 u8 u16 u32 u64 u128 f32 f64 char str string bytes byte_buf
        option unit unit_struct newtype_struct seq tuple tuple_struct map enum identifier
        ignored_any
    }
}

/// The CSV header of a row type: its field names, in order.
pub fn header<R: Deserialize<'static>>() -> &'static [&'static str] {
    let mut fields: &'static [&'static str] = &[];
    let _ = R::deserialize(FieldNames(&mut fields));
    fields
}

/// Writes `rows` to the CSV file `path`, with the header from the row type's field names
/// (also when there are no rows).
pub fn write_csv<R>(path: &Path, rows: &[R]) -> Result<(), ReportError>
where
    R: Serialize + Deserialize<'static>,
{
    let mut w = csv::WriterBuilder::new()
        .has_headers(false)
        .from_writer(Vec::new());
    let failed = |e: csv::Error| ReportError::Io {
        path: path.to_path_buf(),
        source: std::io::Error::other(e.to_string()),
    };
    w.write_record(header::<R>()).map_err(failed)?;
    for r in rows {
        w.serialize(r).map_err(failed)?;
    }
    let bytes = w.into_inner().map_err(|e| failed(e.into_error().into()))?;
    fs::write(path, bytes).map_err(ReportError::io(path))
}

/// One column of a Markdown table: its heading and how to fill a cell from a row.
pub struct Column<'a, T> {
    head: String,
    cell: Box<dyn Fn(&T) -> String + 'a>,
}

/// A column with heading `head` and cells `cell(row)`.
pub fn col<'a, T>(head: impl Into<String>, cell: impl Fn(&T) -> String + 'a) -> Column<'a, T> {
    Column {
        head: head.into(),
        cell: Box::new(cell),
    }
}

fn line(cells: impl Iterator<Item = String>) -> String {
    let mut s = String::from("|");
    for c in cells {
        if c.is_empty() {
            s.push_str(" |");
        } else {
            s.push(' ');
            s.push_str(&c);
            s.push_str(" |");
        }
    }
    s.push('\n');
    s
}

/// A Markdown table: a heading line, the rule, and one line per row (each ending in `\n`).
pub fn markdown<'r, T: 'r>(
    rows: impl IntoIterator<Item = &'r T>,
    cols: &[Column<'_, T>],
) -> String {
    let mut md = line(cols.iter().map(|c| c.head.clone()));
    md.push('|');
    for _ in cols {
        md.push_str("---|");
    }
    md.push('\n');
    for r in rows {
        md.push_str(&line(cols.iter().map(|c| (c.cell)(r))));
    }
    md
}

/// `{x:.Ne}`, or `—` for a value that is not finite.
pub fn fmt_e(x: f64, digits: usize) -> String {
    if x.is_finite() {
        format!("{x:.digits$e}")
    } else {
        "—".into()
    }
}

/// A duration in s, ms or µs.
pub fn fmt_time(t: f64) -> String {
    if t >= 1.0 {
        format!("{t:.2} s")
    } else if t >= 1e-3 {
        format!("{:.2} ms", t * 1e3)
    } else {
        format!("{:.1} µs", t * 1e6)
    }
}

/// The verdict of a target in a section's table: `**met**` or `**not met**`.
pub fn met(ok: bool) -> &'static str {
    if ok {
        "**met**"
    } else {
        "**not met**"
    }
}
