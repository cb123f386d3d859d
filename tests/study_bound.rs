//! A tolerance study's error is not below its Cramér–Rao bound (issue 13). The bound limits the mean
//! squared error of any unbiased estimate, so the statistic compared with it is the RMS of the difference
//! over the trials, √(mean d²) (the mean |d| is smaller for any spread). The check, per value:
//!     RMS d ≥ bound · (1 − 3·se),   se = sd(d²) / (2·mean(d²)·√n)
//! se is the Monte-Carlo relative standard error of the RMS over n trials (delta method), so an estimator
//! that reaches the bound exactly passes in all but ~0.1 % of runs, while a bound computed from the wrong
//! noise (before this test: from the record's high band, 0.06 µm for every ρ, 4× the achieved error at
//! ρ = 1e-6) fails. The noise densities span 1e-6 to 1e-5 m/s²/√Hz (0.1–1 µg/√Hz, piezo to MEMS-grade
//! accelerometers), where noise, not a model bias, dominates the error, and the estimate is expected near
//! the bound: the test also requires RMS d ≤ 1.5·bound at 1e-5 (the SNR-weighted fusion is the
//! Gauss–Markov estimate of the model, docs/methods.md).

use crate::util::root;
use vmt::scenario::Scenario;
use vmt::study::{run_study, Vary};

#[test]
fn a_studys_rms_error_is_not_below_its_cramer_rao_bound() {
    let sc = Scenario::load(&root().join("scenarios/study_accel.toml")).unwrap();
    let vary = Vary::parse("sensors.acc_z.noise_density=1e-6,3e-6,1e-5").unwrap();
    let rows = run_study(&sc, &vary, 40, (0, 1), None, None).unwrap();
    for &v in &vary.values {
        let r: Vec<_> = rows.iter().filter(|r| r.value == v && r.estimate.contains("acc_z")).collect();
        assert_eq!(r.len(), 40);
        let d2: Vec<f64> = r.iter().map(|r| r.difference * r.difference).collect();
        let n = d2.len() as f64;
        let mean = d2.iter().sum::<f64>() / n;
        let sd = (d2.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (n - 1.0)).sqrt();
        let rms = mean.sqrt();
        let se = sd / (2.0 * mean * n.sqrt());
        let bound = r.iter().map(|r| r.bound).sum::<f64>() / n;
        println!("ρ = {v:.0e}: RMS d {:.4} µm, bound {:.4} µm, MC rel. SE {:.3}", rms * 1e6, bound * 1e6, se);
        assert!(bound.is_finite() && bound > 0.0, "ρ = {v}: no bound");
        assert!(rms >= bound * (1.0 - 3.0 * se), "ρ = {v}: RMS d {rms:e} m below the bound {bound:e} m");
        if v == 1e-5 {
            assert!(rms <= 1.5 * bound, "ρ = {v}: RMS d {rms:e} m far above the bound {bound:e} m");
        }
    }
}
