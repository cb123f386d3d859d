//! Issue 17: the laser line-set identifier (seeds 001/003, `vmt_estimators::laser_ls::identify`) on line
//! sets made by a generator independent of vmt's simulator: the first-order volumetric model of one X axis,
//! `reading = u·(E(q) + ε(q) × r) + zero of the line + noise`, with random smooth error-motion profiles
//! (random Fourier features, correlation length 0.15–0.6 of the travel), random irregular targets, and random
//! line layouts (3–9 lines, measuring points anywhere in a 0.6 × 0.6 × 1.2 m box on the carriage, beams
//! along X, Y or Z), plus deliberately rank-deficient layouts.

use crate::gen::laser::{line_value, random_layout, random_motions, LineLayout as Layout, Smooth, BEAMS};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};
use rayon::prelude::*;
use vmt_estimators::laser_ls::{identify, Axis, AxisModel, IdOptions, Model, Reading};

/// Readings of a layout for error motions `motions` (EXX, EYX, EZX, EAX, EBX, ECX) with noise from `rng`
/// (none when `rng` is None).
fn readings(l: &Layout, motions: &[Smooth; 6], mut rng: Option<&mut ChaCha8Rng>) -> Vec<Reading> {
    let mut out = Vec::new();
    for (li, line) in l.lines.iter().enumerate() {
        let zero = 1e-5 * li as f64;
        for &q in &l.targets {
            let noise: f64 = rng.as_deref_mut().map_or(0.0, |g| StandardNormal.sample(g));
            out.push(Reading {
                q: vec![q],
                point: line.0,
                direction: line.1,
                value: line_value(motions, line, q) + zero + l.sigma * noise,
                sigma: l.sigma,
                line: Some(li),
            });
        }
    }
    out
}

fn model(l: &Layout) -> Model {
    Model { axes: vec![AxisModel::with_nodes(Axis::X, &l.targets)], squareness: false }
}

/// Per layout: over 60 noise draws, each identified value's error (against the identification of the
/// noise-free readings, which is the truth in the reporting gauge: the model is exact at the targets) in
/// units of its reported σ.
fn layout_stats(seed: u64) -> Option<(usize, f64, Vec<f64>, Vec<String>)> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let l = random_layout(&mut rng);
    let travel = l.targets[l.targets.len() - 1];
    let motions = random_motions(&mut rng, travel);
    let m = model(&l);
    let opts = IdOptions::default();
    let truth = match identify(&readings(&l, &motions, None), &m, &opts) {
        Ok(t) => t,
        Err(e) => {
            println!("layout {seed}: {e}");
            return None;
        }
    };
    let draws = 60;
    let mut z: Vec<Vec<f64>> = Vec::new();
    for k in 0..draws {
        let mut g = ChaCha8Rng::seed_from_u64(seed * 1000 + k);
        let id = identify(&readings(&l, &motions, Some(&mut g)), &m, &opts).unwrap();
        let mut zs = Vec::new();
        for (p, t) in id.profiles.iter().zip(&truth.profiles) {
            for i in 0..p.values.len() {
                if let Some(s) = p.std_errors[i] {
                    if s > 1e-9 * l.sigma {
                        zs.push((p.values[i] - t.values[i]) / s);
                    }
                }
            }
        }
        z.push(zs);
    }
    let n = z[0].len();
    if n == 0 {
        // Every value confounded (a rank-deficient layout): the identifier must say what it cannot see.
        println!(
            "layout {seed}: {} lines, no observable value; not observable: {}",
            l.lines.len(),
            truth.unobservable.join("; ")
        );
        return Some((l.lines.len(), truth.rank as f64, Vec::new(), truth.unobservable));
    }
    // spread/σ per parameter: √(mean z²) over the draws (zero-mean: the model is exact)
    let per_param: Vec<f64> =
        (0..n).map(|j| (z.iter().map(|d| d[j] * d[j]).sum::<f64>() / draws as f64).sqrt()).collect();
    Some((l.lines.len(), truth.rank as f64, per_param, truth.unobservable))
}

/// Issue 17, must show: the reported σ against the spread over ≥ 50 draws within 20 %, on 30 random
/// layouts × 60 noise draws (rank-deficient ones included: what they cannot see is named). Per layout the pooled ratio spread/σ = √(mean over parameters and draws of
/// z²) has a sampling spread of about 1/√(2·60·n_eff) ≤ 9 %; 20 % is the limit. Each parameter's
/// own ratio (60 draws: ±9 % 1σ) is summarised (mean, 95th percentile) and must stay within 0.6–1.5
/// (beyond 5σ of its sampling spread).
#[test]
fn laser_identification_sigma_matches_spread_on_random_layouts() {
    let t0 = std::time::Instant::now();
    let stats: Vec<_> = (0..30u64).into_par_iter().filter_map(|s| layout_stats(100 + s)).collect();
    assert_eq!(stats.len(), 30, "every layout identifies (possibly nothing observable)");
    let with_values = stats.iter().filter(|s| !s.2.is_empty()).count();
    println!("{with_values} of 30 random layouts determine at least one value; the others name what they cannot see");
    assert!(with_values >= 15, "only {with_values} of 30 layouts determine a value");
    let mut all = Vec::new();
    for (lines, rank, per, unobs) in &stats {
        if per.is_empty() {
            assert!(!unobs.is_empty(), "a layout with nothing observable names nothing unobservable");
            continue;
        }
        let pooled = (per.iter().map(|r| r * r).sum::<f64>() / per.len() as f64).sqrt();
        println!(
            "{lines} lines, rank {rank}: {} parameters, pooled spread/σ {pooled:.3}; not observable: {}",
            per.len(),
            if unobs.is_empty() { "-".to_string() } else { unobs.join("; ") }
        );
        assert!((pooled - 1.0).abs() <= 0.2, "pooled spread/σ {pooled:.3} not within 20 %");
        all.extend(per.iter().copied());
    }
    let mut s = all.clone();
    s.sort_by(f64::total_cmp);
    let mean = all.iter().sum::<f64>() / all.len() as f64;
    println!(
        "{} layouts with values, {} parameters × 60 draws: spread/σ mean {mean:.3}, p5 {:.3}, p95 {:.3}, min {:.3}, max {:.3} ({:.1} s)",
        with_values,
        all.len(),
        s[s.len() / 20],
        s[s.len() * 19 / 20],
        s[0],
        s[s.len() - 1],
        t0.elapsed().as_secs_f64()
    );
    assert!(s[0] >= 0.6 && s[s.len() - 1] <= 1.5, "a parameter's spread/σ outside 0.6–1.5");
}

/// Rank-deficient layouts name what they cannot see: X beams only (no straightness, no roll), and lines
/// whose points share one height and one sideways offset (the angles about the beams cannot be told apart).
#[test]
fn rank_deficient_layouts_name_the_unobservable_errors() {
    let mut rng = ChaCha8Rng::seed_from_u64(5);
    let motions = random_motions(&mut rng, 1.0);
    let targets: Vec<f64> = (0..11).map(|i| i as f64 * 0.1).collect();
    // Only X beams, at three points: positioning, pitch and yaw are seen; EYX, EZX and EAX are not.
    let x_only = Layout {
        targets: targets.clone(),
        lines: vec![([0.0, 0.0, 0.2], BEAMS[0]), ([0.2, 0.25, 0.8], BEAMS[0]), ([0.0, -0.25, 1.1], BEAMS[0])],
        sigma: 1e-7,
    };
    let id = identify(&readings(&x_only, &motions, None), &model(&x_only), &IdOptions::default()).unwrap();
    println!("X beams only: rank {}, not observable: {:?}", id.rank, id.unobservable);
    let text = id.unobservable.join(" ");
    for name in ["EYX", "EZX", "EAX"] {
        assert!(text.contains(name), "{name} not named: {text}");
        let p = id.profile(name).unwrap();
        assert!(p.std_errors.iter().skip(1).all(|s| s.is_none()), "{name} given a σ");
    }
    for name in ["EXX", "EBX", "ECX"] {
        assert!(!text.contains(name), "{name} wrongly named: {text}");
    }
    // One Y beam at r = (0, 0, 0.5): it reads EYX − 0.5·EAX only; the two cannot be told apart (and
    // nothing else is seen).
    let y_one = Layout { targets, lines: vec![([0.0, 0.0, 0.5], BEAMS[1])], sigma: 1e-7 };
    let id = identify(&readings(&y_one, &motions, None), &model(&y_one), &IdOptions::default()).unwrap();
    println!("one Y line: rank {}, not observable: {:?}", id.rank, id.unobservable);
    let text = id.unobservable.join(" ");
    assert!(text.contains("EYX") && text.contains("EAX"), "the EYX/EAX combination not named: {text}");
}
