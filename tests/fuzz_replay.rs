//! The fuzz targets of `fuzz/` (vmt::fuzz) replayed on stable (issue 14): each target runs over a
//! seed corpus (valid inputs of every reader) and over deterministic mutations of it (byte flips,
//! interesting tokens — nan, inf, 1e300, -1, 4294967295, quotes, brackets, deep nesting — deleted and
//! duplicated spans). A panic in any reader fails the test, naming the target and the input.

use crate::util::root;
use rand::{Rng, SeedableRng};
use std::cell::Cell;
use std::sync::Once;

/// Mutations per target: small enough for CI (a few seconds), enough to reach every reader's
/// number, structure and encoding paths from the seeds.
const MUTATIONS: usize = 400;

const TOKENS: &[&str] = &[
    "nan",
    "inf",
    "-inf",
    "-1",
    "0",
    "1e300",
    "1e-300",
    "4294967295",
    "18446744073709551616",
    "\"",
    "[",
    "]",
    "{",
    "}",
    ",",
    "\n",
    "=",
    "<",
    ">",
    "/>",
    "</",
    "<link name=\"a\">",
    "[[runs]]",
    "[[sensors]]",
    "\u{feff}",
    "\u{ff}",
];

fn mutate(seed: &[u8], rng: &mut rand_chacha::ChaCha8Rng) -> Vec<u8> {
    let mut v = seed.to_vec();
    for _ in 0..rng.gen_range(1..=4) {
        let n = v.len().max(1);
        let at = rng.gen_range(0..n).min(v.len());
        match rng.gen_range(0..5) {
            0 if !v.is_empty() => {
                let i = rng.gen_range(0..v.len());
                v[i] ^= 1 << rng.gen_range(0..8);
            }
            1 => {
                let t = TOKENS[rng.gen_range(0..TOKENS.len())].as_bytes();
                v.splice(at..at, t.iter().copied());
            }
            2 if !v.is_empty() => {
                let end = (at + rng.gen_range(1..64)).min(v.len());
                v.drain(at..end);
            }
            3 if !v.is_empty() => {
                let end = (at + rng.gen_range(1..200)).min(v.len());
                let span: Vec<u8> = v[at..end].to_vec();
                v.splice(at..at, span);
            }
            _ => {
                // Replace a number-like run of digits with a token.
                if let Some(i) = v.iter().skip(at).position(|c| c.is_ascii_digit()) {
                    let i = at + i;
                    let j = v[i..].iter().position(|c| !c.is_ascii_digit() && *c != b'.').map_or(v.len(), |k| i + k);
                    let t = TOKENS[rng.gen_range(0..9)].as_bytes();
                    v.splice(i..j, t.iter().copied());
                }
            }
        }
    }
    v
}

thread_local! {
    /// Whether a panic on this thread is an expected one of [`panics_quietly`] (not printed).
    static QUIET: Cell<bool> = const { Cell::new(false) };
}

/// Whether `f` panics, without printing the panic message. All the tests share one process (one test
/// binary): the panic hook is process-wide, so it is replaced once, by one that stays silent only on a
/// thread inside this function and passes every other panic (another test's failure) to the previous
/// hook. (Taking the hook and setting it back per call raced between concurrent tests and could leave
/// the silent hook in place, hiding every later failure message.)
fn panics_quietly(f: impl FnOnce()) -> bool {
    static HOOK: Once = Once::new();
    HOOK.call_once(|| {
        let prev = std::panic::take_hook();
        std::panic::set_hook(Box::new(move |info| {
            if !QUIET.with(Cell::get) {
                prev(info)
            }
        }));
    });
    QUIET.with(|q| q.set(true));
    let panicked = std::panic::catch_unwind(std::panic::AssertUnwindSafe(f)).is_err();
    QUIET.with(|q| q.set(false));
    panicked
}

fn replay(name: &str, target: fn(&[u8]), seeds: &[Vec<u8>]) {
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(14);
    let mut inputs: Vec<Vec<u8>> = seeds.to_vec();
    for k in 0..MUTATIONS {
        inputs.push(mutate(&seeds[k % seeds.len()], &mut rng));
    }
    let failures: Vec<String> = inputs
        .iter()
        .filter(|d| panics_quietly(|| target(d)))
        .map(|d| String::from_utf8_lossy(&d[..d.len().min(400)]).into_owned())
        .collect();
    assert!(
        failures.is_empty(),
        "{name}: {} of {} inputs panicked, e.g.:\n{}",
        failures.len(),
        inputs.len(),
        failures[0]
    );
}

fn read(p: &str) -> Vec<u8> {
    std::fs::read(root().join(p)).unwrap()
}

const MANIFEST: &str = "format = \"vmt-measurements/1\"\n[[sensors]]\nname = \"laser\"\nkind = \"laser_linear\"\naxis = \"x\"\nposition = [0.0, 0.0, 0.0]\ndirection = [1.0, 0.0, 0.0]\nsigma = 2e-8\n[[runs]]\nname = \"iso\"\nfile = \"run.csv\"\nprocedure = \"positioning\"\naxis = \"x\"\n";

#[test]
fn scenario_toml_never_panics() {
    replay("scenario_toml", vmt::fuzz::scenario_toml, &[read("tests/data/small.toml"), read("scenarios/default.toml")]);
}

#[test]
fn measurement_set_never_panics() {
    let table = "target,run,direction,laser[um]\n0,1,1,0.1\n0.5,1,1,0.2\n0.5,1,-1,0.3\n0,1,-1,0.1\n";
    let series = "t,laser\n0,0\n0.001,1e-9\n0.002,2e-9\n";
    let seeds = vec![
        format!("{MANIFEST}\n---\n{table}").into_bytes(),
        format!("{}\n---\n{series}", MANIFEST.replace("positioning", "crawl")).into_bytes(),
    ];
    replay("measurement_set", vmt::fuzz::measurement_set, &seeds);
}

#[test]
fn iso230_2_dat_never_panics() {
    let dat = b"UNIT=mm\nTGT_DATA=[0,100,200]\nREF_DATA_FWD=[[0.001,0.002],[0.003,0.001],[0.002,0.002]]\nREF_DATA_BWD=[[0.001,0.002],[0.003,0.001],[0.002,0.002]]\n".to_vec();
    replay("iso230_2_dat", vmt::fuzz::iso230_2_dat, &[dat]);
}

#[test]
fn urdf_never_panics() {
    replay("urdf", vmt::fuzz::urdf, &[read("urdf/slide_column.urdf"), read("urdf/vmc_3axis.urdf")]);
}

#[test]
fn profile_csv_never_panics() {
    let p = b"position,positioning,straightness_y,roll\n0,0,0,0\n0.5,1e-6,2e-6,1e-6\n1,2e-6,0,0\n".to_vec();
    let q = b"position[mm],pitch[urad],pitch_sigma[urad]\n0,1,0.1\n500,2,0.1\n1000,3,0.1\n".to_vec();
    replay("profile_csv", vmt::fuzz::profile_csv, &[p, q]);
}
