//! Interrupted runs never lose or mix outputs (issue 14): `vmt run`, `vmt simulate` and `vmt study`
//! killed (SIGKILL) while they write into a destination that holds a complete output of one scenario
//! (seed A); each killed command runs the other seed. After every kill the destination must hold
//! exactly the complete old output or exactly the complete new one (file names and bytes): never a
//! mix, never nothing. Three kinds of kill per command:
//!
//! - **random**: [`KILLS`] at a uniformly random time in [0, 1.2·T] (T: the median duration of three
//!   full runs, measured first);
//! - **near the end**: [`NEAR_END`] at a uniformly random time in [0.9·T, 1.05·T], where the output is
//!   swapped in (the swap is the command's last file operation), T measured again on a complete run
//!   just before each (the machine's load changes while the tests run);
//! - **at a file-system call**: with `strace` (fault injection, `-e inject=CALL:signal=SIGKILL:when=K`)
//!   the command is killed on entering its K-th call of one file syscall. A first traced run lists
//!   every call that touches the destination or its temporary sibling; [`SYSCALL_KILLS`] are aimed at
//!   them, half per scenario (the number of `write` calls depends on the bytes written): every call
//!   from 3 before to 3 after the rename that swaps the output in (`renameat2(RENAME_EXCHANGE)`, or
//!   the two renames where the system lacks it), the rest spread evenly over the others. Where a kill actually landed is read back from
//!   strace's log (the call left unfinished, `= ?`). A timed kill cannot aim at a window of a few
//!   microseconds; these can, and they land on the swap itself. Without strace this part is skipped
//!   with a visible line (under CI, `.ci/run` installs it and its absence is a failure).
//!
//! The test fails unless, for each command, both outcomes occur (some kills leave the old output,
//! some the new one): a test whose kills all land before the swap could never see a mix. The
//! leftovers of killed runs (`NAME.vmt-partial-PID`) are removed by the next complete run.

use crate::util::{small, vmt};
use rand::{Rng, SeedableRng};
use std::collections::BTreeMap;
use std::io::Write;
use std::os::unix::process::ExitStatusExt;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::{Duration, Instant};

/// Kills at uniformly random times in [0, 1.2·T].
const KILLS: usize = 30;
/// Kills at uniformly random times in [0.9·T, 1.05·T].
const NEAR_END: usize = 10;
/// Kills on entering a file-system call of the output transaction (needs strace), half with each
/// scenario.
const SYSCALL_KILLS: usize = 24;
/// The file-system calls strace watches and kills at.
const FILE_CALLS: &str = "openat,mkdir,mkdirat,write,rename,renameat,renameat2,unlink,unlinkat,rmdir,fsync";

/// A tiny scenario: the small test scenario's positioning test only (3 targets, 2 runs), seed `seed`.
fn tiny(dir: &Path, seed: i64) -> PathBuf {
    let small = small();
    let mut t: toml::Table = toml::from_str(&std::fs::read_to_string(small).unwrap()).unwrap();
    t.insert("seed".into(), toml::Value::Integer(seed));
    let procs = t.get_mut("procedures").unwrap().as_array_mut().unwrap();
    procs.remove(0);
    let iso = procs[0].as_table_mut().unwrap();
    iso.insert("targets".into(), toml::Value::Array(vec![0.1.into(), 0.37.into(), 0.61.into()]));
    let ests = t.get_mut("estimators").unwrap().as_array_mut().unwrap();
    ests.truncate(1);
    let p = dir.join(format!("s{seed}.toml"));
    std::fs::write(&p, toml::to_string(&t).unwrap()).unwrap();
    p
}

/// Every file under `dir` with its bytes (None if `dir` is absent).
fn snapshot(dir: &Path) -> Option<BTreeMap<String, Vec<u8>>> {
    fn walk(root: &Path, d: &Path, out: &mut BTreeMap<String, Vec<u8>>) {
        for e in std::fs::read_dir(d).unwrap().flatten() {
            let p = e.path();
            if p.is_dir() {
                walk(root, &p, out);
            } else {
                out.insert(p.strip_prefix(root).unwrap().to_string_lossy().into_owned(), std::fs::read(&p).unwrap());
            }
        }
    }
    if !dir.is_dir() {
        return None;
    }
    let mut m = BTreeMap::new();
    walk(dir, dir, &mut m);
    Some(m)
}

/// The three commands that write an output directory.
#[derive(Clone, Copy, Debug)]
enum Kind {
    Run,
    Simulate,
    Study,
}

/// `program` (the vmt binary, or strace in front of it) set up to run `kind` on `scenario` into `out`.
fn command_with(program: Command, kind: Kind, scenario: &Path, out: &Path) -> Command {
    let mut c = program;
    match kind {
        Kind::Run => c.arg("run").arg(scenario).arg("-o").arg(out),
        Kind::Simulate => c.arg("simulate").arg(scenario).arg("-o").arg(out),
        Kind::Study => c
            .arg("study")
            .arg(scenario)
            .args(["--vary", "sensors.laser_x3.sigma=1e-8,2e-8", "--trials", "3", "-o"])
            .arg(out),
    };
    // The report header carries the date of the run; a fixed SOURCE_DATE_EPOCH makes two runs of one
    // scenario byte-identical, so a snapshot is either the old or the new output.
    c.env("RAYON_NUM_THREADS", "1")
        .env("SOURCE_DATE_EPOCH", "1700000000")
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::null());
    c
}

fn command(kind: Kind, scenario: &Path, out: &Path) -> Command {
    command_with(vmt(), kind, scenario, out)
}

/// `strace` (following threads, quiet, file descriptors shown with their paths, log to `log`) in
/// front of vmt, with `extra` options.
fn traced(log: &Path, extra: &[String]) -> Command {
    let mut c = Command::new("strace");
    c.args(["-f", "-qq", "-y", "-o"]).arg(log).args(["-e", &format!("trace={FILE_CALLS}")]).args(extra);
    c.arg(env!("CARGO_BIN_EXE_vmt"));
    c
}

/// Runs `kind` to completion with scenario `s` into `out`; returns the duration.
fn full(kind: Kind, s: &Path, out: &Path) -> Duration {
    let t0 = Instant::now();
    let st = command(kind, s, out).status().unwrap();
    assert!(matches!(st.code(), Some(0 | 1)), "{kind:?} failed: {st:?}");
    t0.elapsed()
}

/// What the kills of one command left, by kind of kill.
#[derive(Default)]
struct Tally {
    /// Timed kills (random and near the end) that left the old output / the new one.
    timed_old: usize,
    timed_new: usize,
    /// Timed kills whose command had already finished when the kill came.
    timed_after_exit: usize,
    /// Timed kills sent within ±10 % of T (of the T they were timed on).
    timed_near_t: usize,
    /// Syscall kills that left the old output / the new one.
    call_old: usize,
    call_new: usize,
    /// Syscall kills that landed on a call touching the destination or its temporary sibling.
    call_on_output: usize,
    /// Syscall kills that landed on the swap itself (a rename of the destination, [`is_swap`]).
    call_on_swap: usize,
    /// Each syscall kill: the call aimed at and the call it landed on (for a failure's message).
    call_log: Vec<String>,
    /// T, the median duration of three full runs.
    t: Duration,
    /// Whether strace was there.
    traced: bool,
}

/// The destination with its two complete outputs, and which one it holds now.
struct Dest {
    out: PathBuf,
    scen: [PathBuf; 2],
    snap: [BTreeMap<String, Vec<u8>>; 2],
    current: usize,
}

impl Dest {
    /// Classifies the destination after a kill of a run of the other scenario: true if it holds the
    /// new output (which becomes current), false if the old one; panics on a mix or nothing.
    fn after_kill(&mut self, kind: Kind, what: &str) -> bool {
        let next = 1 - self.current;
        match snapshot(&self.out) {
            Some(s) if s == self.snap[self.current] => false,
            Some(s) if s == self.snap[next] => {
                self.current = next;
                true
            }
            Some(s) => panic!("{kind:?}: {what} left a mix: files {:?}", s.keys().collect::<Vec<_>>()),
            None => panic!("{kind:?}: {what} left no output"),
        }
    }

    /// The leftovers `out.vmt-partial-*` beside the destination.
    fn leftovers(&self) -> Vec<PathBuf> {
        let parent = self.out.parent().unwrap();
        std::fs::read_dir(parent)
            .unwrap()
            .flatten()
            .filter(|e| e.file_name().to_string_lossy().contains("vmt-partial"))
            .map(|e| e.path())
            .collect()
    }
}

/// Kills `kind` at random and near-the-end times, then at file-system calls; returns the tally.
fn kill_trials(kind: Kind, seed: u64) -> Tally {
    let tmp = tempfile::tempdir().unwrap();
    let (a, b) = (tiny(tmp.path(), 1), tiny(tmp.path(), 2));
    let out = tmp.path().join("out");
    full(kind, &b, &out);
    let snap_b = snapshot(&out).unwrap();
    let mut times = vec![full(kind, &a, &out)];
    let snap_a = snapshot(&out).unwrap();
    assert_ne!(snap_a, snap_b, "{kind:?}: the two seeds must give different outputs");
    times.push(full(kind, &b, &out));
    times.push(full(kind, &a, &out));
    times.sort();
    let t = times[1];
    let mut dest = Dest { out, scen: [a, b], snap: [snap_a, snap_b], current: 0 };
    let mut tally = Tally { t, ..Tally::default() };
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    let mut draws: Vec<f64> = (0..KILLS).map(|_| rng.gen_range(0.0..1.2)).collect();
    draws.extend((0..NEAR_END).map(|_| rng.gen_range(0.9..1.05)));
    for (k, u) in draws.into_iter().enumerate() {
        // A near-the-end kill is timed on a complete run just before it (the load of the machine, and
        // so T, changes while the tests run): that run also puts the other output in place.
        let t = if k < KILLS {
            t
        } else {
            let t = full(kind, &dest.scen[1 - dest.current], &dest.out);
            dest.current = 1 - dest.current;
            t
        };
        let wait = t.mul_f64(u);
        let mut child = command(kind, &dest.scen[1 - dest.current], &dest.out).spawn().unwrap();
        std::thread::sleep(wait);
        if child.try_wait().unwrap().is_some() {
            tally.timed_after_exit += 1;
        }
        let _ = child.kill();
        let _ = child.wait();
        tally.timed_near_t += usize::from((0.9..=1.1).contains(&u));
        if dest.after_kill(kind, &format!("kill {k} after {wait:?} ({u:.3}·T)")) {
            tally.timed_new += 1;
        } else {
            tally.timed_old += 1;
        }
    }
    // A complete run cleans the leftovers of the killed ones.
    full(kind, &dest.scen[1 - dest.current], &dest.out);
    dest.current = 1 - dest.current;
    assert!(dest.leftovers().is_empty(), "{kind:?}: leftovers not cleaned: {:?}", dest.leftovers());
    syscall_kills(kind, &mut dest, tmp.path(), &mut tally);
    tally
}

/// One call of a file syscall in a strace log: the call's name, its ordinal among its thread's calls
/// of that name (1-based: strace's `when=` counts per call and per thread), and the log line.
struct Call {
    name: String,
    ordinal: usize,
    line: String,
}

/// The calls of a strace log (`-f -o`: each line starts with the thread id).
fn calls(log: &str) -> Vec<Call> {
    let mut count: BTreeMap<(String, String), usize> = BTreeMap::new();
    let mut v = Vec::new();
    for line in log.lines() {
        let Some((tid, rest)) = line.split_once(' ') else { continue };
        let Some((name, _)) = rest.trim_start().split_once('(') else { continue };
        if !FILE_CALLS.split(',').any(|c| c == name) {
            continue;
        }
        let n = count.entry((tid.to_string(), name.to_string())).or_default();
        *n += 1;
        v.push(Call { name: name.to_string(), ordinal: *n, line: line.to_string() });
    }
    v
}

/// The call a kill landed on, from strace's log: the call left unfinished (`= ?`). Where the log
/// interleaves another thread's line (the end of the process's other threads), the call is split into
/// `NAME(… <unfinished ...>` and `<... NAME resumed>) = ?`: the first part is joined back.
fn landed_call(log: &str) -> String {
    let lines: Vec<&str> = log.lines().collect();
    let Some(k) = lines.iter().position(|l| l.ends_with("= ?")) else { return "(no unfinished call)".into() };
    let line = lines[k];
    let Some((tid, rest)) = line.split_once(' ') else { return line.into() };
    if !rest.trim_start().starts_with("<...") {
        return line.into();
    }
    let start = lines[..k].iter().rev().find(|l| l.starts_with(&format!("{tid} ")) && l.ends_with("<unfinished ...>"));
    match start {
        Some(s) => format!("{} {}", s.trim_end_matches("<unfinished ...>").trim_end(), rest.trim_start()),
        None => line.into(),
    }
}

/// Whether a strace line is a rename of the destination `out` itself (its path quoted whole): the swap,
/// `renameat2(…, RENAME_EXCHANGE)`, or either rename of a two-rename swap where the system lacks it.
fn is_swap(line: &str, out: &str) -> bool {
    let call = line.split_once(' ').map_or(line, |(_, rest)| rest.trim_start());
    ["rename(", "renameat(", "renameat2("].iter().any(|r| call.starts_with(r)) && line.contains(&format!("\"{out}\""))
}

/// Whether strace can trace here (installed, and ptrace allowed).
fn strace_works() -> bool {
    Command::new("strace")
        .args(["-qq", "-o", "/dev/null", "true"])
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::null())
        .status()
        .is_ok_and(|s| s.success())
}

/// The kills at file-system calls: a traced complete run of each scenario lists the calls touching
/// the destination (per scenario: the number of `write` calls depends on the bytes written), then each
/// chosen call kills a run of that scenario on entering it.
fn syscall_kills(kind: Kind, dest: &mut Dest, dir: &Path, tally: &mut Tally) {
    if !strace_works() {
        assert!(std::env::var_os("CI").is_none(), "CI is set but strace is not usable (.ci/run installs it)");
        // Straight to the stderr handle: libtest captures `eprintln!`, and a skip must be seen.
        let line = format!("SKIPPED (strace not usable): {kind:?} killed at file-system calls (kill::)\n");
        let _ = std::io::stderr().lock().write_all(line.as_bytes());
        return;
    }
    tally.traced = true;
    let out_text = dest.out.to_string_lossy().into_owned();
    let log = dir.join("strace.log");
    // The calls aimed at, half per scenario: every call from 3 before to 3 after the swap, the rest
    // spread evenly over the others.
    let mut aims: [std::collections::VecDeque<Call>; 2] = Default::default();
    for _ in 0..2 {
        let next = 1 - dest.current;
        let st = command_with(traced(&log, &[]), kind, &dest.scen[next], &dest.out).status().unwrap();
        assert!(matches!(st.code(), Some(0 | 1)), "{kind:?} under strace failed: {st:?}");
        dest.current = next;
        assert_eq!(snapshot(&dest.out).as_ref(), Some(&dest.snap[next]), "{kind:?}: the traced run's output");
        let on_out: Vec<Call> =
            calls(&std::fs::read_to_string(&log).unwrap()).into_iter().filter(|c| c.line.contains(&out_text)).collect();
        let swap = on_out
            .iter()
            .position(|c| is_swap(&c.line, &out_text))
            .unwrap_or_else(|| panic!("{kind:?}: no rename of the destination in the trace"));
        let near: Vec<usize> = (swap.saturating_sub(3)..(swap + 4).min(on_out.len())).collect();
        let rest: Vec<usize> = (0..on_out.len()).filter(|i| !near.contains(i)).collect();
        let spread = (SYSCALL_KILLS / 2).saturating_sub(near.len()).min(rest.len());
        let mut chosen = near.clone();
        chosen.extend((0..spread).map(|j| rest[j * rest.len() / spread]));
        chosen.sort_unstable();
        let mut on_out: Vec<Option<Call>> = on_out.into_iter().map(Some).collect();
        aims[next] = chosen.into_iter().filter_map(|i| on_out[i].take()).collect();
    }
    // Each aim once: a run of scenario s needs the other's output in place; where a kill left s's
    // own, a complete run of the other puts it back.
    while !(aims[0].is_empty() && aims[1].is_empty()) {
        let next = 1 - dest.current;
        let Some(target) = aims[next].pop_front() else {
            full(kind, &dest.scen[next], &dest.out);
            dest.current = next;
            continue;
        };
        let target = &target;
        // strace counts invocations up to 65535.
        assert!(target.ordinal <= 65_535, "{kind:?}: {} is call {} of its kind", target.line, target.ordinal);
        // A killed run's leftover would add calls (its removal) before the transaction and shift the
        // ordinals: removed here. That the next run removes them is checked above.
        for l in dest.leftovers() {
            std::fs::remove_dir_all(l).unwrap();
        }
        let inject = format!("inject={}:signal=SIGKILL:when={}", target.name, target.ordinal);
        let st =
            command_with(traced(&log, &["-e".into(), inject]), kind, &dest.scen[next], &dest.out).status().unwrap();
        let landed = landed_call(&std::fs::read_to_string(&log).unwrap());
        // strace ends itself with the signal that ended the traced command.
        assert_eq!(
            st.signal(),
            Some(libc::SIGKILL),
            "{kind:?}: not killed at {} #{} ({}): {st:?}",
            target.name,
            target.ordinal,
            target.line
        );
        let line = format!("aimed at {} #{}: {}; landed at: {landed}", target.name, target.ordinal, target.line);
        eprintln!("{kind:?}: {line}");
        tally.call_log.push(line);
        tally.call_on_output += usize::from(landed.contains(&out_text));
        tally.call_on_swap += usize::from(is_swap(&landed, &out_text));
        if dest.after_kill(kind, &format!("a kill at `{landed}`")) {
            tally.call_new += 1;
        } else {
            tally.call_old += 1;
        }
    }
}

#[test]
fn killed_run_simulate_and_study_leave_the_complete_old_or_new_output() {
    let kinds = [Kind::Run, Kind::Simulate, Kind::Study];
    let results: Vec<Tally> = std::thread::scope(|s| {
        let hs: Vec<_> =
            kinds.iter().enumerate().map(|(i, k)| s.spawn(move || kill_trials(*k, 14 + i as u64))).collect();
        hs.into_iter().map(|h| h.join().unwrap()).collect()
    });
    let mut problems = Vec::new();
    for (k, r) in kinds.iter().zip(&results) {
        let timed = KILLS + NEAR_END;
        eprintln!(
            "{k:?} (T = {:.3} s, median of 3 full runs; the near-the-end kills timed on a complete run just before \
             each): {timed} timed kills ({KILLS} in [0, 1.2·T], {NEAR_END} in [0.9·T, 1.05·T]): {} left the old \
             output, {} the new one ({} came after the command had finished); {} were sent within ±10 % of T",
            r.t.as_secs_f64(),
            r.timed_old,
            r.timed_new,
            r.timed_after_exit,
            r.timed_near_t
        );
        if r.traced {
            eprintln!(
                "{k:?}: {} kills at file-system calls: {} left the old output, {} the new one; {} landed on a call \
                 touching the destination or its temporary sibling, {} on the swap (a rename of the destination)",
                r.call_old + r.call_new,
                r.call_old,
                r.call_new,
                r.call_on_output,
                r.call_on_swap
            );
            if r.call_on_swap == 0 {
                problems.push(format!(
                    "{k:?}: no kill at a file-system call landed on the swap:\n{}",
                    r.call_log.join("\n")
                ));
            }
        }
        assert_eq!(r.timed_old + r.timed_new, timed);
        let (old, new) = (r.timed_old + r.call_old, r.timed_new + r.call_new);
        if old == 0 || new == 0 {
            problems.push(format!(
                "{k:?}: {old} kills left the old output and {new} the new one: both must occur, or the kills \
                 missed the moment the output is swapped in"
            ));
        }
    }
    assert!(problems.is_empty(), "{}", problems.join("\n"));
}
