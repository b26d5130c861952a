//! The bad-input corpus (`tests/data/bad/`, made by its `make.py`): every entry of
//! `tests/data/bad/expected.json` through the `clothsr` binary, checked against the outcome it
//! lists. Never a panic; `ok` exits 0 (and a run writes its output); `input` exits 3 with an
//! error naming the file and every word of `mentions`, leaving no output behind; `usage` exits 2.
//! All entries run (a few at a time), and every failure is reported at once.
//!
//! `CLOTHSR_CORPUS_FILTER=text` runs only the entries whose file contains `text`.

use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::Mutex;
use std::time::{Duration, Instant};

use serde::Deserialize;

/// The longest one entry may take before it counts as a hang and is killed. Every entry takes
/// under 3 s (release build, 2 cores); the limit is ten times that, so that a slow or busy
/// machine does not fail them.
const CASE_TIMEOUT: Duration = Duration::from_secs(30);
/// Most entries run at once.
const MAX_JOBS: usize = 4;
/// What the corpus must hold at least.
const MIN_ENTRIES: usize = 45;
/// Largest corpus file, and the whole corpus, bytes.
const MAX_FILE_BYTES: u64 = 50 * 1024;
const MAX_TOTAL_BYTES: u64 = 1024 * 1024;
/// The corpus folders `make.py` writes.
const CORPUS_DIRS: [&str; 5] = ["usd", "obj", "pattern", "models", "misc"];
/// What `clothsr run` says of its output after a failure: only true where it wrote some.
const KEEPS_FRAMES: &str = "keeps the frames published before the failure";

#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "lowercase")]
enum Kind {
    /// `clothsr inspect FILE`.
    Inspect,
    /// `clothsr run FILE --frames 1 --layer off -o OUT`.
    Run,
    /// `clothsr run samples/sheet_sphere.usda --models DIR --frames 1 -o OUT`.
    Models,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "lowercase")]
enum Outcome {
    /// Exit 0.
    Ok,
    /// Exit 3, bad input.
    Input,
    /// Exit 2, bad usage.
    Usage,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct Entry {
    /// Path under `tests/data/bad/` (a folder for `models`).
    file: String,
    command: Kind,
    outcome: Outcome,
    /// Words the error must contain besides the file name.
    mentions: Vec<String>,
    /// Why this outcome (for people; checked only to be there).
    why: String,
}

impl Entry {
    fn label(&self) -> String {
        let command = format!("{:?}", self.command).to_lowercase();
        format!("{} [{command}]", self.file)
    }
}

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

fn corpus() -> PathBuf {
    root().join("tests/data/bad")
}

fn entries() -> Vec<Entry> {
    let path = corpus().join("expected.json");
    let text = std::fs::read_to_string(&path).expect("read tests/data/bad/expected.json");
    serde_json::from_str(&text).expect("tests/data/bad/expected.json: a list of entries")
}

/// What one process did.
struct Finished {
    /// Exit code; `None` when killed by a signal or by the timeout.
    code: Option<i32>,
    /// The signal that ended it (Unix).
    signal: Option<i32>,
    timed_out: bool,
    stderr: String,
    took: Duration,
}

#[cfg(unix)]
fn signal_of(status: &std::process::ExitStatus) -> Option<i32> {
    use std::os::unix::process::ExitStatusExt;
    status.signal()
}

#[cfg(not(unix))]
fn signal_of(_status: &std::process::ExitStatus) -> Option<i32> {
    None
}

/// Runs `clothsr args` in `work` with its output streams in `logs`, killing it after
/// [`CASE_TIMEOUT`].
fn run_clothsr(args: &[&std::ffi::OsStr], work: &Path, logs: &Path) -> Finished {
    let err_path = logs.join("stderr.txt");
    let stdout = std::fs::File::create(logs.join("stdout.txt")).expect("create stdout file");
    let stderr = std::fs::File::create(&err_path).expect("create stderr file");
    let start = Instant::now();
    let mut child = Command::new(env!("CARGO_BIN_EXE_clothsr"))
        .args(args)
        .current_dir(work)
        .env_remove("RUST_LOG")
        .env_remove("CLOTHSR_MODELS")
        .env_remove("CLOTHSR_DEVICE")
        .env("NO_COLOR", "1")
        .stdin(Stdio::null())
        .stdout(stdout)
        .stderr(stderr)
        .spawn()
        .expect("start clothsr");
    let (status, timed_out) = loop {
        if let Some(status) = child.try_wait().expect("wait for clothsr") {
            break (Some(status), false);
        }
        if start.elapsed() > CASE_TIMEOUT {
            // Our own child: end it, and reap it.
            let _ = child.kill();
            let _ = child.wait();
            break (None, true);
        }
        std::thread::sleep(Duration::from_millis(25));
    };
    let took = start.elapsed();
    let bytes = std::fs::read(&err_path).expect("read stderr file");
    Finished {
        code: status.and_then(|s| s.code()),
        signal: status.as_ref().and_then(signal_of),
        timed_out,
        stderr: String::from_utf8_lossy(&bytes).into_owned(),
        took,
    }
}

/// The error clothsr printed: from its last `error:` line to the end.
fn error_text(stderr: &str) -> Option<&str> {
    let start = if stderr.starts_with("error:") {
        Some(0)
    } else {
        stderr.rfind("\nerror:").map(|i| i + 1)
    };
    start.map(|i| stderr[i..].trim_end())
}

/// The end of `text`, for a report: its last few lines, at most about 600 characters.
fn tail(text: &str) -> String {
    let lines: Vec<&str> = text.lines().filter(|l| !l.trim().is_empty()).collect();
    let last = lines[lines.len().saturating_sub(4)..].join("\n      ");
    if last.len() > 600 {
        let mut cut = last.len() - 600;
        while !last.is_char_boundary(cut) {
            cut += 1;
        }
        format!("…{}", &last[cut..])
    } else {
        last
    }
}

/// Files left in `dir`, recursively.
fn leftovers(dir: &Path) -> Vec<String> {
    let mut out = Vec::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        let Ok(read) = std::fs::read_dir(&d) else {
            continue;
        };
        for entry in read.flatten() {
            let p = entry.path();
            if p.is_dir() {
                stack.push(p.clone());
            }
            out.push(
                p.strip_prefix(dir)
                    .map_or_else(|_| p.display().to_string(), |r| r.display().to_string()),
            );
        }
    }
    out.sort();
    out
}

/// Runs one entry; `Err` lists what went wrong.
fn check(entry: &Entry) -> (Duration, Result<(), String>) {
    let input = corpus().join(&entry.file);
    let work = tempfile::tempdir().expect("tempdir");
    let logs = tempfile::tempdir().expect("tempdir");
    let out = work.path().join("out.usdc");
    let sample = root().join("samples/sheet_sphere.usda");
    let args: Vec<&std::ffi::OsStr> = match entry.command {
        Kind::Inspect => vec!["inspect".as_ref(), input.as_os_str()],
        Kind::Run => vec![
            "run".as_ref(),
            input.as_os_str(),
            "--frames".as_ref(),
            "1".as_ref(),
            "--layer".as_ref(),
            "off".as_ref(),
            "-o".as_ref(),
            out.as_os_str(),
        ],
        Kind::Models => vec![
            "run".as_ref(),
            sample.as_os_str(),
            "--models".as_ref(),
            input.as_os_str(),
            "--frames".as_ref(),
            "1".as_ref(),
            "-o".as_ref(),
            out.as_os_str(),
        ],
    };
    let f = run_clothsr(&args, work.path(), logs.path());
    let name = Path::new(&entry.file)
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    let mut problems = Vec::new();
    if f.timed_out {
        problems.push(format!(
            "still running after {} s (a hang), killed",
            CASE_TIMEOUT.as_secs()
        ));
    } else if let Some(sig) = f.signal {
        problems.push(format!("killed by signal {sig}"));
    }
    if f.code == Some(101) || f.stderr.contains("panicked") {
        problems.push("panicked".into());
    }
    let want = match entry.outcome {
        Outcome::Ok => 0,
        Outcome::Usage => 2,
        Outcome::Input => 3,
    };
    if !f.timed_out && f.code != Some(want) {
        problems.push(format!(
            "exit code {}, expected {want} ({:?})",
            f.code.map_or("none".into(), |c| c.to_string()),
            entry.outcome
        ));
    }
    let error = error_text(&f.stderr);
    match entry.outcome {
        Outcome::Ok => {
            if entry.command != Kind::Inspect && f.code == Some(0) && !out.exists() {
                problems.push("exit 0 but no output file".into());
            }
        }
        Outcome::Input | Outcome::Usage => {
            match error {
                None if !f.timed_out => problems.push("no 'error:' message".into()),
                None => {}
                Some(text) => {
                    if !text.contains(&name) {
                        problems.push(format!("the error does not name '{name}'"));
                    }
                    let missing: Vec<&str> = entry
                        .mentions
                        .iter()
                        .filter(|w| !text.contains(w.as_str()))
                        .map(String::as_str)
                        .collect();
                    if !missing.is_empty() {
                        problems.push(format!("the error lacks {missing:?}"));
                    }
                    if text.contains(KEEPS_FRAMES) && !out.exists() {
                        problems.push(format!(
                            "the error says the output '{KEEPS_FRAMES}', but there is no output"
                        ));
                    }
                }
            }
            let left = leftovers(work.path());
            if !left.is_empty() {
                problems.push(format!("files left behind: {left:?}"));
            }
        }
    }
    let result = if problems.is_empty() {
        Ok(())
    } else {
        let shown = match error {
            Some(text) if entry.outcome != Outcome::Ok => text.to_string(),
            _ => f.stderr.clone(),
        };
        Err(format!(
            "{} (expected {:?}: {})\n    - {}\n    stderr: {}",
            entry.label(),
            entry.outcome,
            entry.why,
            problems.join("\n    - "),
            tail(&shown)
        ))
    };
    (f.took, result)
}

/// Runs `entries` a few at a time; the failures, in corpus order.
fn run_all(entries: &[Entry]) -> Vec<String> {
    let jobs = std::thread::available_parallelism()
        .map_or(2, |n| n.get())
        .clamp(1, MAX_JOBS);
    let next = AtomicUsize::new(0);
    let results: Mutex<Vec<(usize, Result<(), String>)>> = Mutex::new(Vec::new());
    std::thread::scope(|s| {
        for _ in 0..jobs {
            s.spawn(|| loop {
                let i = next.fetch_add(1, Ordering::SeqCst);
                let Some(entry) = entries.get(i) else {
                    break;
                };
                let (took, result) = check(entry);
                eprintln!(
                    "{:>6.1} s  {:<4} {}",
                    took.as_secs_f64(),
                    if result.is_ok() { "ok" } else { "FAIL" },
                    entry.label()
                );
                results.lock().expect("results lock").push((i, result));
            });
        }
    });
    let mut results = results.into_inner().expect("results lock");
    results.sort_by_key(|r| r.0);
    results.into_iter().filter_map(|r| r.1.err()).collect()
}

#[test]
fn bad_input_corpus_has_the_expected_outcomes() {
    let all = entries();
    let filter = std::env::var("CLOTHSR_CORPUS_FILTER").unwrap_or_default();
    let chosen: Vec<Entry> = all
        .into_iter()
        .filter(|e| e.file.contains(filter.as_str()))
        .collect();
    let start = Instant::now();
    let failures = run_all(&chosen);
    eprintln!(
        "{} corpus entries in {:.1} s",
        chosen.len(),
        start.elapsed().as_secs_f64()
    );
    assert!(
        failures.is_empty(),
        "{} of {} corpus entries are not as tests/data/bad/expected.json says:\n\n{}\n",
        failures.len(),
        chosen.len(),
        failures.join("\n\n")
    );
}

/// Files and folders of the corpus, relative to it: every file of `usd/`, `obj/`, `pattern/`
/// and `misc/`, and every folder of `models/`.
fn corpus_inputs() -> Vec<String> {
    let dir = corpus();
    let mut out = Vec::new();
    for sub in CORPUS_DIRS {
        let Ok(read) = std::fs::read_dir(dir.join(sub)) else {
            continue;
        };
        for entry in read.flatten() {
            let name = entry.file_name().to_string_lossy().into_owned();
            out.push(format!("{sub}/{name}"));
        }
    }
    out.sort();
    out
}

#[test]
fn bad_input_corpus_is_complete_and_small() {
    let all = entries();
    assert!(
        all.len() >= MIN_ENTRIES,
        "{} entries, at least {MIN_ENTRIES} wanted",
        all.len()
    );
    let mut problems = Vec::new();
    for e in &all {
        let path = corpus().join(&e.file);
        let present = if e.command == Kind::Models {
            path.is_dir()
        } else {
            path.is_file()
        };
        if !present {
            problems.push(format!("{}: missing (run tests/data/bad/make.py)", e.file));
        }
        if e.why.trim().is_empty() {
            problems.push(format!("{}: no 'why'", e.file));
        }
        if e.outcome == Outcome::Ok && !e.mentions.is_empty() {
            problems.push(format!("{}: mentions on an 'ok' entry", e.file));
        }
    }
    for input in corpus_inputs() {
        if !all.iter().any(|e| e.file == input) {
            problems.push(format!("{input}: in the corpus but not in expected.json"));
        }
    }
    let mut total = 0;
    let mut stack = vec![corpus()];
    while let Some(d) = stack.pop() {
        for entry in std::fs::read_dir(&d).expect("read corpus folder").flatten() {
            let p = entry.path();
            if p.is_dir() {
                stack.push(p);
                continue;
            }
            let size = entry.metadata().expect("corpus file metadata").len();
            total += size;
            if size >= MAX_FILE_BYTES {
                problems.push(format!("{}: {size} bytes", p.display()));
            }
        }
    }
    if total >= MAX_TOTAL_BYTES {
        problems.push(format!("the corpus is {total} bytes"));
    }
    assert!(problems.is_empty(), "{}", problems.join("\n"));
}
