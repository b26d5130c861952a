//! Every value-taking flag of every command, given hostile values, is refused when it is
//! parsed, with the flag named, unless the value is one the flag means to take.

use clap::{CommandFactory, Parser};

use super::Cli;

/// Values no flag should take blindly: empty, not a number, negative, huge, the wrong arity,
/// a missing path, a folder.
const HOSTILE: [&str; 8] = ["", "nan", "-1", "1e308", "1,2", "a,b,c", MISSING, "."];

/// A path in a folder that does not exist (made when an output is written).
const MISSING: &str = "/nonexistent/x.usda";

/// Plain names, which a flag naming a file or folder to write may take.
const NAMES: [&str; 5] = ["nan", "-1", "1e308", "1,2", "a,b,c"];

/// The hostile values a flag may take because they mean something to it (it may refuse
/// them too, naming itself: a USD output wants a USD extension).
fn may_take(long: &str, value: &str) -> bool {
    match long {
        // Files to write (any name in a folder that exists) and folders to write into.
        "csv" | "plot" | "coarse-out" | "upsampled-out" | "output" => {
            NAMES.contains(&value) || value == "." || value == MISSING
        }
        // `--rrd` alone: the recording beside the output.
        "rrd" => NAMES.contains(&value) || value.is_empty() || value == MISSING,
        // Folders read (the current one exists), or files or data set folders.
        "out-dir" | "models" | "gt" | "data" | "val-data" | "floor" | "model" | "init"
        | "baseline" => value == ".",
        // Signed, or lists of values.
        "garment-yaw-deg" | "share-min" => value == "-1",
        "ladder-mm" | "depths" | "friction" | "wrinkle-bending" | "bending" => value == "1,2",
        _ => false,
    }
}

/// Every leaf command with its path of names.
fn leaves(cmd: &clap::Command, path: &[String], out: &mut Vec<(Vec<String>, clap::Command)>) {
    let subs: Vec<_> = cmd
        .get_subcommands()
        .filter(|s| s.get_name() != "help")
        .collect();
    if subs.is_empty() {
        out.push((path.to_vec(), cmd.clone()));
    }
    for s in subs {
        let mut p = path.to_vec();
        p.push(s.get_name().to_string());
        leaves(s, &p, out);
    }
}

/// Whether the parse error `e` is about the flag `--long`.
fn names(e: &clap::Error, long: &str) -> bool {
    e.get(clap::error::ContextKind::InvalidArg)
        .is_some_and(|n| n.to_string().contains(&format!("--{long}")))
}

/// A value of the required option `r` that its parser takes, as `--name=value`.
fn valid_value(argv: &[String], r: &clap::Arg) -> String {
    let long = r.get_long().unwrap_or_default();
    let candidates = [
        "1",
        "x.usdc",
        ".",
        "samples/sheet_three_balls.usda",
        "cotton",
    ];
    for v in candidates {
        let mut a = argv.to_vec();
        a.push(format!("--{long}={v}"));
        if !Cli::try_parse_from(&a).is_err_and(|e| names(&e, long)) {
            return format!("--{long}={v}");
        }
    }
    panic!("no value in {candidates:?} for --{long}: add one")
}

#[test]
fn every_flag_refuses_hostile_values_naming_itself() {
    let mut all = Vec::new();
    leaves(&Cli::command(), &[], &mut all);
    let mut wrong = Vec::new();
    let mut flags = 0;
    for (path, leaf) in &all {
        let positionals: Vec<String> = leaf
            .get_positionals()
            .filter(|a| a.is_required_set())
            .map(|_| "samples/sheet_three_balls.usda".to_string())
            .collect();
        let required: Vec<&clap::Arg> = leaf
            .get_arguments()
            .filter(|a| a.is_required_set() && !a.is_positional())
            .collect();
        for arg in leaf.get_arguments() {
            let Some(long) = arg.get_long() else { continue };
            if !arg.get_action().takes_values() || arg.is_global_set() {
                continue;
            }
            flags += 1;
            let mut base = vec!["clothsr".to_string()];
            base.extend(path.iter().cloned());
            base.extend(positionals.iter().cloned());
            for r in required.iter().filter(|r| r.get_id() != arg.get_id()) {
                let v = valid_value(&base, r);
                base.push(v);
            }
            for value in HOSTILE {
                let mut argv = base.clone();
                argv.push(format!("--{long}={value}"));
                let case = format!("{} --{long}={value:?}", path.join(" "));
                match Cli::try_parse_from(&argv) {
                    Ok(_) if !may_take(long, value) => wrong.push(format!("{case}: taken")),
                    Err(e) if !names(&e, long) => {
                        wrong.push(format!("{case}: refused without naming the flag: {e}"))
                    }
                    _ => {}
                }
            }
        }
    }
    assert!(flags > 100, "only {flags} flags found");
    assert!(wrong.is_empty(), "{}", wrong.join("\n"));
}
