//! vmt's error type and a TOML table reader that tracks key paths.
//!
//! DESIGN.md §2: bad input (a malformed TOML or CSV, a NaN, a missing column, a unit that does not
//! fit, a value out of physical range) gets a clear error that names the file, the place (line,
//! column name or TOML key path) and what was expected, and exit code 2. Never a panic.

use std::cell::RefCell;
use std::collections::BTreeSet;
use std::fmt;
use std::path::{Path, PathBuf};
use vmt_sim::Axis;

/// Everything that can go wrong in vmt's file formats and workflows.
#[derive(Debug, thiserror::Error)]
pub enum VmtError {
    /// Bad input: `file: place: message`, e.g.
    /// `scenario.toml: effects.backlash.value: expected a length in metres ≥ 0, got -4e-6`.
    BadInput {
        /// The file at fault (a directory for a measurement set as a whole).
        file: PathBuf,
        /// Where in it: `line 12, column laser_p1`, a key path `effects.backlash.value`, a run
        /// name, or empty for the file as a whole.
        place: String,
        /// What was expected and what was found.
        message: String,
    },
    /// A bad command line (unknown option value, missing argument).
    Usage(String),
    /// An operating-system error while reading or writing `file`.
    Io {
        /// The file or directory concerned.
        file: PathBuf,
        /// What vmt was doing: "reading", "writing", "renaming into place".
        action: String,
        /// The operating system's error.
        #[source]
        source: std::io::Error,
    },
    /// A bug in vmt (an invariant broken); please report it.
    Internal(String),
}

impl fmt::Display for VmtError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            VmtError::BadInput { file, place, message } => {
                if place.is_empty() {
                    write!(f, "{}: {message}", file.display())
                } else {
                    write!(f, "{}: {place}: {message}", file.display())
                }
            }
            VmtError::Usage(m) => write!(f, "usage: {m}"),
            VmtError::Io { file, action, source } => write!(f, "{}: {action}: {source}", file.display()),
            VmtError::Internal(m) => write!(f, "internal error (a bug in vmt): {m}"),
        }
    }
}

impl VmtError {
    /// A bad-input error naming the file, the place and what was expected.
    pub fn bad(file: &Path, place: impl Into<String>, message: impl Into<String>) -> VmtError {
        VmtError::BadInput { file: file.to_path_buf(), place: place.into(), message: message.into() }
    }

    /// An I/O error while doing `action` on `file`. A file that does not exist when reading is
    /// bad input (the user named it), not an I/O failure.
    /// Likewise a directory where a file is expected, a file where a directory is expected, and a
    /// file that is not UTF-8 text (UTF-16, binary).
    pub fn io(file: &Path, action: &str, source: std::io::Error) -> VmtError {
        use std::io::ErrorKind;
        if action.starts_with("reading") {
            let what = match source.kind() {
                ErrorKind::NotFound => Some("no such file or directory"),
                ErrorKind::IsADirectory => Some("a directory where a file is expected"),
                ErrorKind::NotADirectory => Some("a file where a directory is expected"),
                ErrorKind::InvalidData => Some("not UTF-8 text (save it as UTF-8, e.g. not UTF-16)"),
                _ => None,
            };
            if let Some(w) = what {
                return VmtError::bad(file, "", format!("{w} ({action})"));
            }
        }
        VmtError::Io { file: file.to_path_buf(), action: action.to_string(), source }
    }

    /// The text of `file`, refused as bad input when it is larger than `max_bytes` (checked before
    /// reading: the size a file states bounds what is allocated); `what` names it in the messages
    /// ("a compensation table").
    pub fn read_bounded(file: &Path, max_bytes: u64, what: &str) -> Result<String, VmtError> {
        let action = format!("reading {what}");
        let meta = std::fs::metadata(file).map_err(|e| VmtError::io(file, &action, e))?;
        if meta.len() > max_bytes {
            return Err(VmtError::bad(file, "", format!("{} bytes; {what} is at most {max_bytes}", meta.len())));
        }
        std::fs::read_to_string(file).map_err(|e| VmtError::io(file, &action, e))
    }

    /// Process exit code: 2 for bad input and bad usage (DESIGN.md §2), 3 for I/O failures of the
    /// machine (disk full, permission denied; 1 is reserved for an estimate that missed its
    /// tolerance), 70 (EX_SOFTWARE) for internal errors.
    pub fn exit_code(&self) -> i32 {
        match self {
            VmtError::BadInput { .. } | VmtError::Usage(_) => 2,
            VmtError::Io { .. } => 3,
            VmtError::Internal(_) => 70,
        }
    }

    /// True for bad input (exit code 2).
    pub fn is_bad_input(&self) -> bool {
        matches!(self, VmtError::BadInput { .. })
    }
}

/// A number for messages: `-4e-6` for small or large magnitudes, `0.25` otherwise (shortest
/// round-trip digits).
pub fn fmt_num(x: f64) -> String {
    vmt_sim::effects::fmt_num(x)
}

/// What a TOML value is, for messages: `a string "abc"`, `an integer 3`, `a table`.
pub fn describe_value(v: &toml::Value) -> String {
    match v {
        toml::Value::String(s) => format!("a string {s:?}"),
        toml::Value::Integer(i) => format!("an integer {i}"),
        toml::Value::Float(x) => format!("a number {}", fmt_num(*x)),
        toml::Value::Boolean(b) => format!("a boolean {b}"),
        toml::Value::Datetime(d) => format!("a date {d}"),
        toml::Value::Array(a) => format!("an array of {} items", a.len()),
        toml::Value::Table(_) => "a table".to_string(),
    }
}

/// 1-based (line, column) of byte offset `pos` in `text`.
pub fn line_col(text: &str, pos: usize) -> (usize, usize) {
    let pos = pos.min(text.len());
    let before = &text.as_bytes()[..pos];
    let line = before.iter().filter(|&&b| b == b'\n').count() + 1;
    let start = before.iter().rposition(|&b| b == b'\n').map_or(0, |i| i + 1);
    let col = String::from_utf8_lossy(&before[start..]).chars().count() + 1;
    (line, col)
}

/// Parses TOML text; a syntax error names the file, the line and column, and the parser's
/// message (e.g. `model.toml: line 3, column 9: invalid number`).
pub fn parse_toml(file: &Path, text: &str) -> Result<toml::Table, VmtError> {
    toml::from_str::<toml::Table>(text).map_err(|e| {
        let place = match e.span() {
            Some(r) => {
                let (l, c) = line_col(text, r.start);
                format!("line {l}, column {c}")
            }
            None => String::new(),
        };
        VmtError::bad(file, place, format!("malformed TOML: {}", e.message().trim()))
    })
}

/// Reads a TOML table key by key, building the key path of every message
/// (`effects.backlash.value`) and remembering which keys were asked for, so that
/// [`TomlReader::deny_unknown`] can reject the others (a misspelt key is an error, not ignored).
pub struct TomlReader<'a> {
    file: &'a Path,
    prefix: String,
    table: &'a toml::Table,
    asked: RefCell<BTreeSet<String>>,
}

impl<'a> TomlReader<'a> {
    /// A reader of `table`, found in `file` at key path `prefix` (empty for the root).
    pub fn new(file: &'a Path, prefix: &str, table: &'a toml::Table) -> TomlReader<'a> {
        TomlReader { file, prefix: prefix.to_string(), table, asked: RefCell::new(BTreeSet::new()) }
    }

    /// The file being read.
    pub fn file(&self) -> &'a Path {
        self.file
    }

    /// This table's key path (empty for the root).
    pub fn prefix(&self) -> &str {
        &self.prefix
    }

    /// The underlying table.
    pub fn table(&self) -> &'a toml::Table {
        self.table
    }

    /// Full key path of `key`: `prefix.key` (or `key` at the root).
    pub fn path(&self, key: &str) -> String {
        if self.prefix.is_empty() {
            key.to_string()
        } else if key.is_empty() {
            self.prefix.clone()
        } else if key.starts_with('[') {
            format!("{}{key}", self.prefix)
        } else {
            format!("{}.{key}", self.prefix)
        }
    }

    /// A bad-input error at `key` of this table.
    pub fn bad(&self, key: &str, message: impl Into<String>) -> VmtError {
        VmtError::bad(self.file, self.path(key), message)
    }

    /// The raw value of `key` (marks it as known).
    pub fn value(&self, key: &str) -> Option<&'a toml::Value> {
        self.asked.borrow_mut().insert(key.to_string());
        self.table.get(key)
    }

    /// True if `key` is present (marks it as known).
    pub fn has(&self, key: &str) -> bool {
        self.value(key).is_some()
    }

    /// Marks keys as known without reading them.
    pub fn allow(&self, keys: &[&str]) {
        let mut a = self.asked.borrow_mut();
        for k in keys {
            a.insert((*k).to_string());
        }
    }

    /// An optional string.
    pub fn opt_str(&self, key: &str, what: &str) -> Result<Option<&'a str>, VmtError> {
        match self.value(key) {
            None => Ok(None),
            Some(toml::Value::String(s)) => Ok(Some(s.as_str())),
            Some(v) => Err(self.bad(key, format!("expected {what}, got {}", describe_value(v)))),
        }
    }

    /// An optional axis, written as its lower-case letter (`axis = "x"`, FORMAT.md); any other string is
    /// refused with the letters expected.
    pub fn opt_axis(&self, key: &str) -> Result<Option<Axis>, VmtError> {
        match self.opt_str(key, "an axis \"x\", \"y\" or \"z\"")? {
            None => Ok(None),
            Some("x") => Ok(Some(Axis::X)),
            Some("y") => Ok(Some(Axis::Y)),
            Some("z") => Ok(Some(Axis::Z)),
            Some(s) => Err(self.bad(key, format!("expected an axis \"x\", \"y\" or \"z\", got {s:?}"))),
        }
    }

    /// A required string.
    pub fn req_str(&self, key: &str, what: &str) -> Result<&'a str, VmtError> {
        self.opt_str(key, what)?.ok_or_else(|| self.bad(key, format!("missing key: expected {what}")))
    }

    /// An optional finite number (a TOML float or integer), SI.
    pub fn opt_f64(&self, key: &str, what: &str) -> Result<Option<f64>, VmtError> {
        match self.value(key) {
            None => Ok(None),
            Some(v) => value_f64(v)
                .filter(|x| x.is_finite())
                .map(Some)
                .ok_or_else(|| self.bad(key, format!("expected {what}, got {}", describe_value(v)))),
        }
    }

    /// A required finite number.
    pub fn req_f64(&self, key: &str, what: &str) -> Result<f64, VmtError> {
        self.opt_f64(key, what)?.ok_or_else(|| self.bad(key, format!("missing key: expected {what}")))
    }

    /// An optional non-negative integer.
    pub fn opt_u64(&self, key: &str, what: &str) -> Result<Option<u64>, VmtError> {
        match self.value(key) {
            None => Ok(None),
            Some(toml::Value::Integer(i)) if *i >= 0 => Ok(Some(*i as u64)),
            Some(v) => Err(self.bad(key, format!("expected {what}, got {}", describe_value(v)))),
        }
    }

    /// An optional integer.
    pub fn opt_i64(&self, key: &str, what: &str) -> Result<Option<i64>, VmtError> {
        match self.value(key) {
            None => Ok(None),
            Some(toml::Value::Integer(i)) => Ok(Some(*i)),
            Some(v) => Err(self.bad(key, format!("expected {what}, got {}", describe_value(v)))),
        }
    }

    /// An optional boolean.
    pub fn opt_bool(&self, key: &str) -> Result<Option<bool>, VmtError> {
        match self.value(key) {
            None => Ok(None),
            Some(toml::Value::Boolean(b)) => Ok(Some(*b)),
            Some(v) => Err(self.bad(key, format!("expected true or false, got {}", describe_value(v)))),
        }
    }

    /// An optional array of finite numbers.
    pub fn opt_f64_array(&self, key: &str, what: &str) -> Result<Option<Vec<f64>>, VmtError> {
        match self.value(key) {
            None => Ok(None),
            Some(toml::Value::Array(a)) => a
                .iter()
                .enumerate()
                .map(|(i, v)| {
                    value_f64(v).filter(|x| x.is_finite()).ok_or_else(|| {
                        self.bad(&format!("{key}[{i}]"), format!("expected {what}, got {}", describe_value(v)))
                    })
                })
                .collect::<Result<Vec<f64>, VmtError>>()
                .map(Some),
            Some(v) => Err(self.bad(key, format!("expected an array of {what}, got {}", describe_value(v)))),
        }
    }

    /// An optional sub-table, as a reader with the extended key path.
    pub fn opt_table(&self, key: &str) -> Result<Option<TomlReader<'a>>, VmtError> {
        match self.value(key) {
            None => Ok(None),
            Some(toml::Value::Table(t)) => Ok(Some(TomlReader::new(self.file, &self.path(key), t))),
            Some(v) => Err(self.bad(key, format!("expected a table, got {}", describe_value(v)))),
        }
    }

    /// An optional array of tables (`[[key]]` or `key = [{...}, ...]`), each as a reader with
    /// key path `prefix.key[i]`.
    pub fn opt_tables(&self, key: &str) -> Result<Option<Vec<TomlReader<'a>>>, VmtError> {
        match self.value(key) {
            None => Ok(None),
            Some(toml::Value::Array(a)) => {
                a.iter()
                    .enumerate()
                    .map(|(i, v)| match v {
                        toml::Value::Table(t) => Ok(TomlReader::new(self.file, &format!("{}[{i}]", self.path(key)), t)),
                        other => Err(self
                            .bad(&format!("{key}[{i}]"), format!("expected a table, got {}", describe_value(other)))),
                    })
                    .collect::<Result<Vec<TomlReader<'a>>, VmtError>>()
                    .map(Some)
            }
            Some(v) => Err(self.bad(key, format!("expected an array of tables, got {}", describe_value(v)))),
        }
    }

    /// Rejects every key of the table that was never asked for, listing the known keys.
    pub fn deny_unknown(&self) -> Result<(), VmtError> {
        let asked = self.asked.borrow();
        if let Some(k) = self.table.keys().find(|k| !asked.contains(k.as_str())) {
            let known: Vec<&str> = asked.iter().map(|s| s.as_str()).collect();
            return Err(self.bad(k, format!("unknown key `{k}` (known keys here: {})", known.join(", "))));
        }
        Ok(())
    }
}

/// A TOML float or integer as f64 (integers convert exactly up to 2^53).
fn value_f64(v: &toml::Value) -> Option<f64> {
    match v {
        toml::Value::Float(x) => Some(*x),
        toml::Value::Integer(i) => Some(*i as f64),
        _ => None,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bad_input_names_file_place_and_expectation_and_exits_2() {
        let e = VmtError::bad(
            Path::new("scenario.toml"),
            "effects.backlash.value",
            "expected a length in metres ≥ 0, got -4e-6",
        );
        assert_eq!(e.to_string(), "scenario.toml: effects.backlash.value: expected a length in metres ≥ 0, got -4e-6");
        assert_eq!(e.exit_code(), 2);
        let io = VmtError::io(Path::new("x"), "writing", std::io::Error::from(std::io::ErrorKind::PermissionDenied));
        assert_eq!(io.exit_code(), 3, "I/O failures of the machine exit 3 (issue 14)");
        let nf =
            VmtError::io(Path::new("x.toml"), "reading the model", std::io::Error::from(std::io::ErrorKind::NotFound));
        assert_eq!(nf.exit_code(), 2);
    }

    #[test]
    fn malformed_toml_reports_line_and_column() {
        let text = "a = 1\nb = [1, 2\nc = 3\n";
        let e = parse_toml(Path::new("m.toml"), text).unwrap_err();
        let s = e.to_string();
        assert!(s.starts_with("m.toml: line "), "{s}");
        assert!(s.contains("malformed TOML"), "{s}");
    }

    #[test]
    fn reader_builds_key_paths_and_rejects_unknown_keys() {
        let t = parse_toml(Path::new("m.toml"), "[effects.backlash]\nvalue = \"big\"\nvalu = 1\n").unwrap();
        let r = TomlReader::new(Path::new("m.toml"), "", &t);
        let eff = r.opt_table("effects").unwrap().unwrap();
        let b = eff.opt_table("backlash").unwrap().unwrap();
        let e = b.opt_f64("value", "a length in metres").unwrap_err();
        assert_eq!(e.to_string(), "m.toml: effects.backlash.value: expected a length in metres, got a string \"big\"");
        let e = b.deny_unknown().unwrap_err().to_string();
        assert!(e.contains("effects.backlash.valu: unknown key `valu`"), "{e}");
    }

    #[test]
    fn line_col_counts_from_one() {
        assert_eq!(line_col("ab\ncd", 4), (2, 2));
        assert_eq!(line_col("ab", 0), (1, 1));
    }
}
