//! Value parsers of the command line: every flag's value becomes a checked, typed value when
//! it is parsed, so a bad one is refused naming its flag (exit 2) before any work starts.

use std::path::{Path, PathBuf};

/// A parser of a number in `[lo, hi]` (`(lo, hi]` when `open_below`).
fn number(
    lo: f64,
    hi: f64,
    open_below: bool,
) -> impl Fn(&str) -> Result<f64, String> + Clone + Send + Sync + 'static {
    move |s: &str| {
        let v: f64 = s
            .trim()
            .parse()
            .map_err(|_| format!("'{s}' is not a number"))?;
        let above = if open_below { v > lo } else { v >= lo };
        if v.is_finite() && above && v <= hi {
            Ok(v)
        } else {
            let open = if open_below { '(' } else { '[' };
            Err(format!("'{s}': expected a number in {open}{lo}, {hi}]"))
        }
    }
}

/// A number in `(0, hi]`.
pub(crate) fn positive(hi: f64) -> impl Fn(&str) -> Result<f64, String> + Clone + Send + Sync {
    number(0.0, hi, true)
}

/// A number in `[0, hi]`.
pub(crate) fn non_negative(hi: f64) -> impl Fn(&str) -> Result<f64, String> + Clone + Send + Sync {
    number(0.0, hi, false)
}

/// A number in `[lo, hi]`.
pub(crate) fn within(
    lo: f64,
    hi: f64,
) -> impl Fn(&str) -> Result<f64, String> + Clone + Send + Sync {
    number(lo, hi, false)
}

/// The largest length in millimetres a flag takes (a 10 m edge, offset or jitter).
pub(crate) const MAX_MM: f64 = 1e4;

/// The largest time in seconds a flag takes (an hour).
pub(crate) const MAX_S: f64 = 3600.0;

/// The largest dimensionless factor or gain a flag takes.
pub(crate) const MAX_FACTOR: f64 = 1e6;

/// `x,y,z`: three finite numbers, each at most 1000 in size (metres: a kilometre).
pub(crate) fn triple(s: &str) -> Result<[f64; 3], String> {
    let parts: Vec<&str> = s.split(',').map(str::trim).collect();
    let values: Vec<f64> = parts.iter().filter_map(|p| p.parse().ok()).collect();
    match values[..] {
        [x, y, z] if parts.len() == 3 && values.iter().all(|v| v.is_finite() && v.abs() <= 1e3) => {
            Ok([x, y, z])
        }
        _ => Err(format!(
            "'{s}': expected three numbers x,y,z, each within ±1000"
        )),
    }
}

/// `on` or `off`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub(crate) enum Switch {
    /// On.
    On,
    /// Off.
    Off,
}

impl From<Switch> for bool {
    fn from(s: Switch) -> bool {
        s == Switch::On
    }
}

/// A parser of `on` or `off` into a bool ([`Switch`]).
pub(crate) fn on_off() -> impl clap::builder::TypedValueParser<Value = bool> {
    use clap::builder::TypedValueParser;
    clap::builder::EnumValueParser::<Switch>::new().map(bool::from)
}

/// A file or folder that exists.
pub(crate) fn input(s: &str) -> Result<PathBuf, String> {
    let p = PathBuf::from(s);
    if s.is_empty() {
        return Err("an empty path".into());
    }
    match std::fs::metadata(&p) {
        Ok(_) => Ok(p),
        Err(e) => Err(format!("{s}: {e}")),
    }
}

/// A file that exists.
pub(crate) fn input_file(s: &str) -> Result<PathBuf, String> {
    let p = input(s)?;
    if p.is_dir() {
        return Err(format!("{s} is a folder: expected a file"));
    }
    Ok(p)
}

/// A folder that exists.
pub(crate) fn input_dir(s: &str) -> Result<PathBuf, String> {
    let p = input(s)?;
    if !p.is_dir() {
        return Err(format!("{s} is not a folder"));
    }
    Ok(p)
}

/// Checks that the folders `p` goes in are folders where they exist (the missing ones are
/// made when it is written).
fn no_file_in_the_way(s: &str, p: &Path) -> Result<(), String> {
    for d in p.ancestors().skip(1).filter(|d| !d.as_os_str().is_empty()) {
        if d.exists() && !d.is_dir() {
            return Err(format!("{s}: {} is a file, not a folder", d.display()));
        }
    }
    Ok(())
}

/// A file to write: not empty, not a folder, with no file where its folders go.
pub(crate) fn output_file(s: &str) -> Result<PathBuf, String> {
    if s.is_empty() {
        return Err("an empty path".into());
    }
    let p = PathBuf::from(s);
    if p.is_dir() {
        return Err(format!("{s} is a folder: expected a file name"));
    }
    no_file_in_the_way(s, &p)?;
    Ok(p)
}

/// A file to write, or nothing (`""`: the command's default place).
pub(crate) fn output_file_or_default(s: &str) -> Result<PathBuf, String> {
    if s.is_empty() {
        return Ok(PathBuf::new());
    }
    output_file(s)
}

/// A USD file to write (`.usd`, `.usda`, `.usdc`).
pub(crate) fn output_usd(s: &str) -> Result<PathBuf, String> {
    let p = output_file(s)?;
    clothsr::io::usd::check_extension(&p).map_err(|e| e.to_string())?;
    Ok(p)
}

/// A folder to write into (made when missing), not a file.
pub(crate) fn output_dir(s: &str) -> Result<PathBuf, String> {
    if s.is_empty() {
        return Err("an empty path".into());
    }
    let p = PathBuf::from(s);
    if p.exists() && !p.is_dir() {
        return Err(format!("{s} is a file: expected a folder"));
    }
    no_file_in_the_way(s, &p)?;
    Ok(p)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn numbers_are_finite_and_in_range() {
        let p = positive(10.0);
        assert_eq!(p("2.5"), Ok(2.5));
        for bad in ["0", "-1", "nan", "inf", "1e308", "10.5", "", "x"] {
            assert!(p(bad).is_err(), "{bad}");
        }
        assert_eq!(non_negative(1.0)("0"), Ok(0.0));
        assert_eq!(within(-5.0, 5.0)("-5"), Ok(-5.0));
        assert!(within(-5.0, 5.0)("-5.1").is_err());
    }

    #[test]
    fn triples_take_three_finite_numbers() {
        assert_eq!(triple("1, -2,3e-1"), Ok([1.0, -2.0, 0.3]));
        for bad in ["1,2", "-1", "nan,0,0", "1e308,0,0", "1,2,3,4", "", "a,b,c"] {
            assert!(triple(bad).is_err(), "{bad}");
        }
    }

    #[test]
    fn paths_are_checked_for_what_they_name() {
        let dir = tempfile::tempdir().unwrap();
        let file = dir.path().join("a.usda");
        std::fs::write(&file, "#usda 1.0\n").unwrap();
        let (d, f) = (dir.path().to_str().unwrap(), file.to_str().unwrap());
        assert!(input_file(f).is_ok() && input_file(d).is_err());
        assert!(input_dir(d).is_ok() && input_dir(f).is_err());
        assert!(input("").is_err() && input(&format!("{d}/missing")).is_err());
        assert!(output_usd(&format!("{d}/out.usdc")).is_ok());
        assert!(output_usd(&format!("{d}/out.obj")).is_err());
        assert!(output_usd(&format!("{d}/missing/out.usdc")).is_ok());
        assert!(output_usd(&format!("{f}/out.usdc")).is_err());
        assert!(output_dir(&format!("{f}/new")).is_err());
        assert!(output_file(d).is_err() && output_dir(f).is_err());
        assert!(output_dir(&format!("{d}/new")).is_ok());
    }
}
