//! Least-squares reference line (ISO 230-1): straightness and profiles are reported about it.

/// Fits y ≈ a + b·x by ordinary least squares and returns (a, b).
///
/// With fewer than two distinct x values the slope is 0 and `a` is the mean of y.
pub fn fit_line(x: &[f64], y: &[f64]) -> (f64, f64) {
    assert_eq!(x.len(), y.len(), "fit_line: x and y differ in length");
    let n = x.len() as f64;
    if x.is_empty() {
        return (0.0, 0.0);
    }
    let mx = x.iter().sum::<f64>() / n;
    let my = y.iter().sum::<f64>() / n;
    let sxx: f64 = x.iter().map(|xi| (xi - mx) * (xi - mx)).sum();
    let sxy: f64 = x.iter().zip(y).map(|(xi, yi)| (xi - mx) * (yi - my)).sum();
    let b = if sxx > 0.0 { sxy / sxx } else { 0.0 };
    (my - b * mx, b)
}

/// Returns y − (a + b·x) with (a, b) the least-squares line through (x, y).
pub fn remove_line(x: &[f64], y: &[f64]) -> Vec<f64> {
    let (a, b) = fit_line(x, y);
    x.iter().zip(y).map(|(xi, yi)| yi - a - b * xi).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn recovers_an_exact_line_and_leaves_zero_residual() {
        let x: Vec<f64> = (0..11).map(|i| i as f64 * 0.1).collect();
        let y: Vec<f64> = x.iter().map(|xi| 3e-6 - 2e-5 * xi).collect();
        let (a, b) = fit_line(&x, &y);
        assert!((a - 3e-6).abs() < 1e-18 && (b + 2e-5).abs() < 1e-18);
        assert!(remove_line(&x, &y).iter().all(|r| r.abs() < 1e-18));
    }

    #[test]
    fn residual_of_a_parabola_is_orthogonal_to_the_line() {
        // Hand-worked: x = 0, 1, 2; y = x² → line 1/3·(−1) + 2x: a = −1/3, b = 2.
        let (a, b) = fit_line(&[0.0, 1.0, 2.0], &[0.0, 1.0, 4.0]);
        assert!((a + 1.0 / 3.0).abs() < 1e-15 && (b - 2.0).abs() < 1e-15);
    }
}
