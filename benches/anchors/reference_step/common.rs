// The step server's body, shared by every version of vmt-sim it is built against (issue 15: the rapier
// reference step measured against the code of the day the issue was filed, in one run). Included by
// the example the driver `reference_step_ab.py` writes into each tree, after that tree's `api_*.rs`,
// which defines `Case` and `cases()` (the same three cases as benches/sim_step.rs, spelled in that tree's API) and
// `model(urdf text, &AxisConfig, fast) -> Option<AxisModel>` (the model on the rapier engine, or on the fast
// engine when `fast` and the tree has one); the URDF is that tree's slide_column.urdf.
//
// Protocol: arguments CASE (an index into `cases()`) and optionally ENGINE (reference, the default, or
// fast: trees from ce7e26e on); then each stdin line "N" runs N steps of the same
// workload as benches/sim_step.rs's `Runner` (start at rest at x = 0.2 m, constant feed, reversing at
// 0.1 and 0.9 m) and prints the wall time of those N steps in ns; the line "0" prints the final body
// position and rotation (so the versions can be seen to have run the same motion) and ends.
use std::io::{BufRead, Write};
use std::time::Instant;

/// The stretch of the travel the command sweeps, m (benches/sim_step.rs's `SWEEP`).
const SWEEP: (f64, f64) = (0.1, 0.9);

fn main() {
    let all = cases();
    let args: Vec<String> = std::env::args().collect();
    let case = args.get(1).and_then(|a| a.parse::<usize>().ok()).and_then(|i| all.get(i));
    let fast = match args.get(2).map(String::as_str) {
        None | Some("reference") => Some(false),
        Some("fast") => Some(true),
        Some(_) => None,
    };
    let (Some(case), Some(fast)) = (case, fast) else {
        eprintln!("usage: reference_step_server CASE [reference|fast] (CASE an index below {})", all.len());
        std::process::exit(2);
    };
    let text = include_str!(concat!(env!("CARGO_MANIFEST_DIR"), "/../urdf/slide_column.urdf"));
    let Some(model) = model(text, &case.cfg, fast) else {
        eprintln!("reference_step_server: this tree's vmt-sim has no fast engine");
        std::process::exit(2);
    };
    let mut sim = AxisSim::new(&model, &case.truth, 0.2);
    let (mut x, mut feed) = (0.2, case.feed);
    let mut out = std::io::stdout().lock();
    for line in std::io::stdin().lock().lines() {
        let Ok(n) = line.unwrap_or_default().trim().parse::<u64>() else {
            eprintln!("reference_step_server: each input line must be a step count");
            std::process::exit(2);
        };
        if n == 0 {
            let s = sim.sample(Command { pos: x, vel: feed, acc: 0.0 });
            writeln!(out, "final {}: x_cmd {x:e} m, body position {:?} m, rotation {:?} rad", case.name, s.pos, s.rot)
                .unwrap();
            return;
        }
        let t0 = Instant::now();
        for _ in 0..n {
            x += feed * model.dt;
            if !(SWEEP.0..=SWEEP.1).contains(&x) {
                feed = -feed;
            }
            sim.step(Command { pos: x, vel: feed, acc: 0.0 });
        }
        writeln!(out, "{}", t0.elapsed().as_nanos()).unwrap();
        out.flush().unwrap();
    }
}
