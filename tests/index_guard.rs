//! Index guards (issue 14): every place in vmt's release code where an input-derived number becomes an
//! index or a size says what guards it, so that a new unguarded one fails here.
//!
//! **What it scans.** The non-test code (each file up to its `#[cfg(test)]`) of `src/`, `sim/src/`,
//! `estimators/src/`, `core/src/` and `report/src/`, for the three forms through which bad input reached
//! an index or an allocation:
//!
//! - **`as usize`**: a float (or a wider or signed integer) made a count or an index. The cast saturates
//!   (NaN → 0, −x → 0, +∞ → `usize::MAX`): an unchecked value becomes an out-of-range index, a silent 0
//!   or a `usize::MAX` allocation (issue 14: `n_targets = 1e9`, `rate = 1e12`). Each one needs an
//!   `// index:` reason — always, because the value's origin cannot be read from the line.
//! - **`len() - k`**: the last elements of a container whose length comes from the data. On an empty or
//!   short container it underflows (a panic in a debug build, `usize::MAX`-ish in release).
//! - **an index that subtracts**, `x[n - 1]`, `t[i - k]`: the same, and the `t[1] − t[0]` family.
//!
//! A `len() - k` or subtracting index is accepted when the code of its function before it (from the
//! `fn` line to the site) shows a length guard — one of [`LENGTH_GUARDS`]: a comparison of `len()` or
//! of a count with a small literal (`n < 2`, `k > 0`), `is_empty()`, a loop from 1, `saturating_sub`,
//! or one of the project's named minimum-length checks. Otherwise, and for every `as usize`, the
//! function must say in an `// index:` comment (on the line, or anywhere in the function before it)
//! what makes the value safe: which check bounds it, or why it is not input-derived.
//!
//! **What it proves.** No such site is added without a guard a reader can check: a new one fails with
//! its file and line. When it was written the scan saw 28 casts, 37 `len() - k` and 74 subtracting
//! indices; 51 of these sites had no visible guard. Each was read and had one (an earlier check, a type
//! invariant such as `CompensationTable::new`'s ≥ 2 nodes, or a bounded formatting count), now named
//! in 35 `// index:` comments (one per function). For scale: clippy's `indexing_slicing` counts about
//! 1 040 index and slice expressions in the same code; the three forms are the ones whose index is
//! computed from a value rather than a loop bound. Reading them also found two unguarded places
//! of a neighbouring kind, fixed with bad-input cases: the trial number of a merged shard (`-1`, `1.5`
//! and `nan` became trial 0) and the laser-line procedures of multi-axis scenarios (no size budget:
//! `rate = 1e12` aborted, `dwell = 1e9` hung).
//!
//! **What it cannot prove.** It reads text, not types or values: that a named guard bounds the right
//! container by the right length, or that a reason is true, is left to review (the bad-input suite and
//! the fuzz targets exercise many of these sites with bad input; they do not reach all). It does not
//! look at literal indices (`p[0]`, `t[1]`: most are on fixed-size arrays, which the compiler checks,
//! and a text scan cannot tell them from slices), at indices by a loop variable within its container's
//! range, or at `[a..b]` ranges without a subtraction; the `t[1]` panic of issue 14 is covered by its
//! own bad-input test (`a_crawl_shorter_than_two_samples_exits_2_naming_the_ssi_check`). `.clamp(` is
//! the clamp test's (`cli_contract::every_clamp_has_literal_bounds_or_says_why_they_are_ordered`).

use crate::util::{root, rust_files};

/// Texts that, before a site in its function, show a length or count check (see the module doc), besides
/// a comparison with an integer literal ([`compares_with_count`]).
pub const LENGTH_GUARDS: &[&str] = &[
    "is_empty()",
    "saturating_sub",
    "checked_sub",
    "in 1..",
    "(1..",
    ".first()",
    ".last()",
    // The project's minimum-length checks.
    "min_len(",
    "check_min(",
    "check_series(",
    "check_points(",
    "validate_run(",
    "TooFew",
];

/// The line without its `//` comment and with string literals emptied (so `"a - b"` is not code).
fn code_of(line: &str) -> String {
    let mut out = String::new();
    let (mut in_str, mut escaped) = (false, false);
    let chars: Vec<char> = line.chars().collect();
    let mut i = 0;
    while i < chars.len() {
        let c = chars[i];
        if in_str {
            if escaped {
                escaped = false;
            } else if c == '\\' {
                escaped = true;
            } else if c == '"' {
                in_str = false;
                out.push('"');
            }
        } else if c == '"' {
            in_str = true;
            out.push('"');
        } else if c == '/' && chars.get(i + 1) == Some(&'/') {
            break;
        } else {
            out.push(c);
        }
        i += 1;
    }
    out
}

/// Whether `code` holds `len()` followed by a subtraction (`len() - 1`, `len()-k`).
fn subtracts_from_len(code: &str) -> bool {
    code.match_indices("len()").any(|(i, m)| code[i + m.len()..].trim_start().starts_with('-'))
}

/// Whether `code` indexes with an expression that subtracts: `x[n - 1]`, `v[(i - 1) % m]` (an index
/// follows a name, `)` or `]`; an array literal `[a - b, c]` follows `=`, `(` or `,` and is not one).
fn index_subtracts(code: &str) -> bool {
    let b = code.as_bytes();
    for (i, &c) in b.iter().enumerate() {
        if c != b'[' || i == 0 {
            continue;
        }
        let prev = b[i - 1];
        if !(prev.is_ascii_alphanumeric() || prev == b'_' || prev == b')' || prev == b']') {
            continue;
        }
        // The bracket's content, up to its matching `]`.
        let mut depth = 0usize;
        let mut j = i;
        while j < b.len() {
            match b[j] {
                b'[' => depth += 1,
                b']' => {
                    depth -= 1;
                    if depth == 0 {
                        break;
                    }
                }
                _ => {}
            }
            j += 1;
        }
        let inner = &code[i + 1..j.min(code.len())];
        // A binary minus (a space on both sides): not `-1.0` as a value, not `->`.
        if inner.contains(" - ") {
            return true;
        }
    }
    false
}

/// Whether `text` compares something with an integer literal (`n < 2`, `k > 0`, `m < 16`; not a float
/// such as `x < 0.5`), or compares a `len()`.
fn compares_with_count(text: &str) -> bool {
    for op in [" < ", " <= ", " > ", " >= ", " == ", " != "] {
        for (i, _) in text.match_indices(op) {
            let rest = &text[i + op.len()..];
            let digits = rest.len() - rest.trim_start_matches(|c: char| c.is_ascii_digit()).len();
            let next = rest[digits..].chars().next();
            if digits > 0 && !next.is_some_and(|c| c == '.' || c == 'e' || c.is_alphanumeric()) {
                return true;
            }
        }
    }
    ["len() <", "len() >", "len() ==", "len() !="].iter().any(|p| text.contains(p))
}

#[test]
fn every_input_derived_index_says_what_guards_it() {
    let mut files = Vec::new();
    for dir in ["src", "sim/src", "estimators/src", "core/src", "report/src"] {
        rust_files(&root().join(dir), &mut files);
    }
    files.sort();
    let (mut seen, mut unguarded) = ([0usize; 3], Vec::new());
    for f in &files {
        let text = std::fs::read_to_string(f).unwrap();
        let lines: Vec<&str> = text.lines().collect();
        // The unit tests sit at the end of a file, after `#[cfg(test)]`: not release code.
        let end = lines.iter().position(|l| l.trim() == "#[cfg(test)]").unwrap_or(lines.len());
        let mut fn_start = 0;
        for i in 0..end {
            let trimmed = lines[i].trim_start();
            if trimmed.contains("fn ") && !trimmed.starts_with("//") {
                fn_start = i;
            }
            if trimmed.starts_with("//") {
                continue;
            }
            let code = code_of(lines[i]);
            let cast = code.contains(" as usize");
            let from_len = subtracts_from_len(&code);
            let sub_index = index_subtracts(&code);
            if !(cast || from_len || sub_index) {
                continue;
            }
            for (k, hit) in [cast, from_len, sub_index].into_iter().enumerate() {
                seen[k] += usize::from(hit);
            }
            // The function so far, and the comment block above the site (for a site on its fn line).
            let above = lines[..i].iter().rev().take_while(|l| l.trim_start().starts_with("//")).count();
            let from = fn_start.min(i - above);
            let body = &lines[from..=i];
            let reason = body.iter().any(|l| l.contains("// index:"));
            let code_so_far: Vec<String> = lines[fn_start..=i].iter().map(|l| code_of(l)).collect();
            let guard =
                code_so_far.iter().any(|c| LENGTH_GUARDS.iter().any(|g| c.contains(g)) || compares_with_count(c));
            if !(reason || !cast && guard) {
                let what = [(cast, "as usize"), (from_len, "len() - k"), (sub_index, "[… - …]")]
                    .iter()
                    .filter(|(h, _)| *h)
                    .map(|(_, w)| *w)
                    .collect::<Vec<_>>()
                    .join(", ");
                unguarded.push(format!(
                    "{}:{}: {what}: {}",
                    f.strip_prefix(root()).unwrap().display(),
                    i + 1,
                    lines[i].trim()
                ));
            }
        }
    }
    // The scan reads the sources: each form occurs in today's code.
    assert!(seen.iter().all(|n| *n > 10), "the scan found only {seen:?} sites: is it reading the sources?");
    assert!(
        unguarded.is_empty(),
        "{} index or size site(s) from input-derived values with neither a visible length guard in their \
         function nor an `// index:` reason (see tests/index_guard.rs):\n{}",
        unguarded.len(),
        unguarded.join("\n")
    );
}

#[test]
fn the_scan_recognises_each_form() {
    assert!(subtracts_from_len("let last = t[t.len() - 1];"));
    assert!(subtracts_from_len("x.len()-2"));
    assert!(!subtracts_from_len("x.len().saturating_sub(1)"));
    assert!(index_subtracts("let d = t[n - 1] - t[0];"));
    assert!(index_subtracts("a[(m - q) % m]"));
    assert!(!index_subtracts("let v = [a - b, c];"));
    assert!(!index_subtracts("let v = x[i] - x[0];"));
    assert_eq!(code_of("let s = \"a[n - 1]\"; // x[n - 1]"), "let s = \"\"; ");
    assert!(compares_with_count("if n < 2 {"));
    assert!(compares_with_count("if m < 16 {"));
    assert!(compares_with_count("if v.len() < k {"));
    assert!(!compares_with_count("if x < 0.5 {"));
    assert!(!compares_with_count("if x > 1e-9 {"));
}
