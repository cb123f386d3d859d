//! Encoder logs as channels of the model-check loop (issue 19): the physics of a ball-screw axis
//! seen by its linear scale and its motor's rotary encoder in a time series.
//!
//! A position loop with gain kv (1/s) drives the motor so that its feedback follows the command;
//! the screw carries the table through its lead error and its play (backlash b); the scale reads
//! the table with its interpolation error. With x_m the motor position (linear equivalent), x_t
//! the table:
//!
//! ```text
//! ẋ_m = ff·ẋ_cmd + kv·(x_cmd − feedback)                 (P position loop, feed-forward ff)
//! scale − motor = E(x) + A_l·sin(2πx/p_l + φ_l) + play_b(t) + A_i·sin(2πx_s/p_i + φ_i)
//! ```
//!
//! The difference scale − motor isolates the transmission (lead error E, cyclic lead, the play)
//! and the scale's interpolation error at the scale's reading x_s, whatever encoder closes the
//! loop; the loop encoder against the command is the following error. In a semi-closed loop
//! (feedback = motor) motor − command = (1 − ff)·(L_kv[x_cmd] − x_cmd) with L_kv the first-order
//! lag ([`first_order_lag`]). In a closed loop (feedback = scale) the motor follows the command
//! less the transmission T = scale − motor:
//!
//! ```text
//! motor − command = (1 − ff)·(L_kv[x_cmd] − x_cmd) − L_kv[T]
//! ```
//!
//! (ẋ_m = ff·ẋ_cmd + kv·(x_cmd − x_m − T) is linear: L_kv[ẋ_cmd] = kv·(x_cmd − L_kv[x_cmd])). The
//! model's T (its fitted and given transmission terms, never the measured scale − motor, whose
//! noise the loop would filter into the prediction) enters the following channel as −L_kv[T]:
//! every design column and known prediction is coupled so in one place, [`close_loop`], with kv
//! the stack's loop gain ([`Stack::loop_kv`]: the model's servo_lag kv, re-set after a fit; an
//! infinite gain, L = identity, for a model without servo_lag, which says the loop follows
//! exactly).
//!
//! A controller samples its loop every h (1/h the servo rate, 1–16 kHz) and holds the motor's
//! velocity command over the tick: x_{k+1} = x_k + kv·h·(u_k − x_k). For an input linear over a
//! log interval Δ the error e = u − x then obeys e(Δ) = s/kv + (e(0) − s/kv)·(1 − kv·h)^{Δ/h}:
//! the continuous law with the decay rate kv' = −ln(1 − kv·h)/h and the lag scaled by
//! g = kv'/kv ≈ 1 + kv·h/2. The fit's kv is kv'; the servo_lag gain takes g (times 1 − ff) on the
//! command; the transmission, not fed forward, passes the loop as −[T + g·(L_kv'[T] − T)], with g
//! fitted ([`loop_gain_step`], [`Stack::loop_gain`]; 1 % of a 1 µm lead at the loop's bandwidth is
//! 10 nm, two to three times a rotary encoder's noise).

use super::*;
use vmt_estimators::cpu::clear_upper_state;
use vmt_estimators::modelcheck::Complex64;

/// What an encoder channel of a time series holds (module doc).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub enum EncoderRole {
    /// scale − motor, m: the transmission and the scale's interpolation error, evaluated at the
    /// scale's reading (the channel's `x`); `drive` is the motor reading at each sample (m), which
    /// moves the nut through the play.
    Transmission { drive: Vec<f64> },
    /// An encoder − command, m: the following error of the loop, L_kv[command] − command;
    /// `s_transmission` is 1 when the channel also carries the transmission (a lone scale in a
    /// semi-closed loop), else 0; `closed` when the scale closes the loop and the run's
    /// transmission channel drives this one through it (−L_kv[T], [`close_loop`]).
    /// `command_sigma`: each sample's standard uncertainty of the command (m; empty when it is
    /// written with every digit), read from a column written to a decimal resolution
    /// ([`super::command::smooth_command`]): the reading's error δ passes into this channel's
    /// residual as −L_kv[δ] ≈ −δ (a smooth δ, below the loop's bandwidth), so it adds δ's
    /// variance to the channel's noise ([`super::report::st_sigma`]).
    Following { command: Vec<f64>, command_sigma: Vec<f64>, s_transmission: f64, closed: bool },
}

impl EncoderRole {
    /// Sensitivity to the transmission terms (lead error, cyclic lead, backlash, interpolation).
    pub(crate) fn s_transmission(&self) -> f64 {
        match self {
            EncoderRole::Transmission { .. } => 1.0,
            EncoderRole::Following { s_transmission, .. } => *s_transmission,
        }
    }
}

/// The signature of a first-order following error on channel `c`: L_kv[command] − command at each
/// sample (0 on channels that are not [`EncoderRole::Following`]).
pub(crate) fn following_error(c: &Channel, kv: f64) -> Vec<f64> {
    match &c.encoder {
        Some(EncoderRole::Following { command, .. }) => {
            let lag = first_order_lag(&c.t, command, kv);
            lag.iter().zip(command).map(|(a, b)| a - b).collect()
        }
        Some(EncoderRole::Transmission { .. }) | None => vec![0.0; c.y.len()],
    }
}

/// A column's passage through a closed position loop (module doc): on every following channel
/// closed by the scale, −L_kv[the column on its run's transmission channel] is added, kv =
/// [`Stack::loop_kv`] (∞: the identity). Columns zero on the transmission (offsets, servo_lag)
/// pass unchanged.
pub(crate) fn close_loop(st: &Stack, col: &mut [f64]) {
    close_loop_each(st, &mut [col]);
}

/// Columns per block of [`columns_each`]'s closed loop: each block's lags in one pass over the
/// samples ([`close_loop_each`]), the blocks side by side.
pub(crate) const LOOP_COLUMNS: usize = 8;

/// [`close_loop`] for several columns (each n values in stack order) at once: each closed pair's
/// lag in one pass over its samples for all of them ([`first_order_lag_each`]), the same bits as
/// [`close_loop`] column by column.
pub(crate) fn close_loop_each<C: AsMut<[f64]> + AsRef<[f64]>>(st: &Stack, cols: &mut [C]) {
    let starts = st.channel_starts();
    for (j, k) in closed_pairs(st) {
        let c = &st.chans[j];
        // index: a pair's channels hold c.y.len() rows each (`closed_pairs`), at their starts.
        let (tr, fo) = (starts[k]..starts[k] + c.y.len(), starts[j]..starts[j] + c.y.len());
        // The columns this pair moves: non-zero on its transmission channel.
        let moved: Vec<usize> =
            (0..cols.len()).filter(|&q| cols[q].as_ref()[tr.clone()].iter().any(|v| *v != 0.0)).collect();
        let inputs: Vec<&[f64]> = moved.iter().map(|&q| &cols[q].as_ref()[tr.clone()]).collect();
        let lagged = if st.loop_kv.is_finite() {
            first_order_lag_each(&c.t, &inputs, st.loop_kv)
        } else {
            inputs.iter().map(|t| t.to_vec()).collect()
        };
        for (&q, mut through) in moved.iter().zip(lagged) {
            let col = cols[q].as_mut();
            // T + g·(L_kv[T] − T), in place of the lag.
            through.iter_mut().zip(&col[tr.clone()]).for_each(|(l, t)| *l = t + st.loop_gain * (*l - t));
            for (y, l) in col[fo.clone()].iter_mut().zip(through) {
                *y -= l;
            }
        }
    }
}

/// [`close_loop`] for a wave of period `p` (m) in the scale's reading — the sine and cosine
/// columns (`sin`, `cos`) of an interpolation error, s·sin θ and s·cos θ with θ = 2π·x_t/p at the
/// table's position x_t = x − `shift` (x the transmission channel's reading, `shift` per sample in
/// stack order, empty for none: [`Stack::interp_shift`]) — whose frequency in time, ω = 2πv/p, a
/// log at speed samples far below its Nyquist rate (a 20 µm period at 0.1 m/s is 5 kHz), so that
/// [`first_order_lag`] of the logged samples would lag an alias. The loop's response L_kv[e^{iθ}]
/// comes from [`wave_lag`] (θ linear in time between samples: exact at a constant speed, and
/// through a reversal's changing speed, where the steady response of the local speed was not:
/// generator draw 2008's reversal kept normalised RMS 1.71 on its motor channel with it), and
///
/// ```text
/// L[sin θ] = Im L[e^{iθ}],  L[cos θ] = Re L[e^{iθ}]
/// ```
///
/// is subtracted on every following channel closed by the scale as −[s·w + g·(L[w] − w)] for each
/// wave column w (kv = [`Stack::loop_kv`], g = [`Stack::loop_gain`]; kv = ∞: the identity, as
/// [`close_loop`]). A servo that samples the scale at its own rate aliases such a wave too, which
/// no log column can show.
pub(crate) fn close_loop_wave(st: &Stack, p: f64, shift: &[f64], sin: &mut [f64], cos: &mut [f64]) {
    clear_upper_state();
    let starts = st.channel_starts();
    let (kv, g) = (st.loop_kv, st.loop_gain);
    for (j, k) in closed_pairs(st) {
        let tr = &st.chans[k];
        let m = st.chans[j].y.len();
        let (k0, s) = (starts[k], tr.s_chain());
        if (k0..k0 + m).all(|q| sin[q] == 0.0 && cos[q] == 0.0) {
            continue;
        }
        let theta: Vec<f64> =
            (0..m).map(|i| TWO_PI * (tr.x[i] - shift.get(k0 + i).copied().unwrap_or(0.0)) / p).collect();
        let h = st.servo_period;
        if kv.is_finite() && h > 0.0 {
            // The servo's own samples of the wave, through its discrete loop: the response itself.
            for (i, (ls, lc)) in wave_lag_sampled(&tr.t, &theta, kv, h).into_iter().enumerate() {
                sin[starts[j] + i] -= s * ls;
                cos[starts[j] + i] -= s * lc;
            }
            continue;
        }
        let lagged =
            if kv.is_finite() { wave_lag(&tr.t, &theta, kv) } else { theta.iter().map(|t| t.sin_cos()).collect() };
        for (i, (th, (ls, lc))) in theta.iter().zip(lagged).enumerate() {
            let (ws, wc) = th.sin_cos();
            sin[starts[j] + i] -= s * (ws + g * (ls - ws));
            cos[starts[j] + i] -= s * (wc + g * (lc - wc));
        }
    }
}

/// The response z(t) of ż = kv·(e^{iθ(t)} − z) to a unit wave whose phase θ (rad) is given at the
/// sample times `t` (s) and linear in time between them, from the settled state of the first
/// interval (z₀ = H(ω₀)·e^{iθ₀}). Exact per interval of length h with ω = (θ₁ − θ₀)/h:
///
/// ```text
/// z₁ = H·e^{iθ₁} + (z₀ − H·e^{iθ₀})·e^{−kv·h},   H = kv/(kv + iω)
/// ```
///
/// kv in 1/s. Returns (Im z, Re z) at every sample: the responses to sin θ and cos θ (the system is
/// real). Non-increasing times hold z.
pub fn wave_lag(t: &[f64], theta: &[f64], kv: f64) -> Vec<(f64, f64)> {
    clear_upper_state();
    let n = t.len().min(theta.len());
    // The loop's response kv/(kv + iω) to a phasor of angular frequency ω.
    let transfer = |om: f64| Complex64::new(kv, 0.0) / Complex64::new(kv, om);
    let mut out = Vec::with_capacity(n);
    if n == 0 {
        return out;
    }
    let om0 = if n > 1 && t[1] > t[0] { (theta[1] - theta[0]) / (t[1] - t[0]) } else { 0.0 };
    let mut z = transfer(om0) * Complex64::cis(theta[0]);
    out.push((z.im, z.re));
    for i in 1..n {
        let h = t[i] - t[i - 1];
        if h > 0.0 {
            let hw = transfer((theta[i] - theta[i - 1]) / h);
            let (before, after) = (hw * Complex64::cis(theta[i - 1]), hw * Complex64::cis(theta[i]));
            z = after + (z - before) * (-kv * h).exp();
        }
        out.push((z.im, z.re));
    }
    out
}

/// (following channel closed by the scale, its run's transmission channel of the same length):
/// the pairs [`close_loop`] and [`close_loop_wave`] couple.
fn closed_pairs(st: &Stack) -> Vec<(usize, usize)> {
    st.chans
        .iter()
        .enumerate()
        .filter(|(_, c)| matches!(c.encoder, Some(EncoderRole::Following { closed: true, .. })))
        .filter_map(|(j, c)| {
            st.chans
                .iter()
                .position(|q| {
                    q.run == c.run
                        && matches!(q.encoder, Some(EncoderRole::Transmission { .. }))
                        && q.y.len() == c.y.len()
                })
                .map(|k| (j, k))
        })
        .collect()
}

/// One Gauss–Newton step for the gain g of a closed loop's transmission path
/// ([`Stack::loop_gain`]), jointly with the fit's linear parameters: the fit `fs` of `model` on
/// `st` predicts T + g·(L_kv[T] − T) on its following channels, linear in g, so its derivative is
/// the difference z of the predictions at g + 1 and g (every fitted column and given effect
/// through the loop: a wave's through [`close_loop_wave`]). With r the fit's residual (orthogonal
/// to its design A) and z⊥ = z less its weighted projection on A:
///
/// ```text
/// δg = Σ w²·r·z / Σ w²·z⊥²
/// ```
///
/// (the regression of r on z alone, Σ w²·z² in the denominator, is the step with every other
/// parameter held: the shapes and kv take up part of g's signature, and that step covered about
/// 64 % of the way per refit on generator draw 2000, six refits of 6.5 s each). `w` = 1/σ in stack
/// order. None without a closed loop or a finite kv, or with nothing that moves through the loop.
pub(crate) fn loop_gain_step(st: &Stack, model: &Model, fs: &FitState, sigma: &Sigma, w: &[f64]) -> Option<f64> {
    if !st.loop_kv.is_finite() || !has_closed_loop(st.chans) {
        return None;
    }
    let up = st.with_loop(st.loop_kv, st.loop_gain + 1.0);
    let mut z: Vec<f64> =
        given_prediction(&up, model).iter().zip(given_prediction(st, model)).map(|(a, b)| a - b).collect();
    for (col_up, (col, c)) in design(&up, &fs.terms).iter().zip(fs.cols.iter().zip(&fs.coefs)) {
        if *c != 0.0 {
            z.iter_mut().zip(col_up.iter().zip(col)).for_each(|(z, (a, b))| *z += c * (a - b));
        }
    }
    let (_, z_perp) = solve_blocks(st, &z, &fs.cols, sigma).ok()?;
    gauss_newton_increment(&z, &z_perp, &fs.residual, w)
}

/// The Gauss–Newton increment of one nonlinear parameter whose derivative column is `z`, with the
/// fit's linear parameters free: Σ w²·r·z / Σ w²·z⊥² (`z_perp` = z less its weighted projection
/// on the fit's design, `r` the fit's residual, `w` = 1/σ; [`loop_gain_step`]). None when z⊥
/// vanishes.
pub(crate) fn gauss_newton_increment(z: &[f64], z_perp: &[f64], r: &[f64], w: &[f64]) -> Option<f64> {
    let (mut num, mut den) = (0.0, 0.0);
    for (k, wk) in w.iter().enumerate() {
        let w2 = wk * wk;
        num += w2 * r[k] * z[k];
        den += w2 * z_perp[k] * z_perp[k];
    }
    (den > 0.0 && num.is_finite()).then(|| num / den)
}

/// [`wave_lag`] for a loop that samples its feedback every `h` seconds and holds the motor's
/// velocity over each tick (module doc): z_{k+1} = a·z_k + (1 − a)·e^{iθ_k} at the ticks, with
/// a = e^{−kv·h} (kv the continuous equivalent the fit holds, 1/s) and θ_k the wave's phase at
/// tick k (linear in time between the log samples, which fall on ticks: a controller logs its own
/// cycle). A wave faster than the servo's Nyquist rate 1/(2h) — an interpolation error at speed —
/// reaches the motor at its alias, which the continuous law cannot show (generator draw 2000: a
/// 10.08 µm wave at 21.3 mm/s is 2 115 Hz; a 1 kHz servo sees 115 Hz, which the loop follows by
/// kv/ω ≈ 8 % and the 111 Hz log shows at 3.7 Hz, a 5.8 mm wave that `diagnose` took for a
/// cyclic lead, ΔBIC −418). Per log interval of n ticks and phase step δ per tick, exactly:
///
/// ```text
/// z_n = aⁿ·z₀ + (1 − a)·e^{iθ₀}·(e^{inδ} − aⁿ)/(e^{iδ} − a),   z₀ = (1 − a)/(e^{iδ₀} − a)·e^{iθ₀} (settled)
/// ```
///
/// n = the interval over h, rounded (0: z held). Returns (Im z, Re z) at every sample: the
/// responses to sin θ and cos θ.
pub fn wave_lag_sampled(t: &[f64], theta: &[f64], kv: f64, h: f64) -> Vec<(f64, f64)> {
    clear_upper_state();
    let n = t.len().min(theta.len());
    let a = (-kv * h).exp();
    // index: called with 1 ≤ i < n, n the shorter of the two lengths.
    let ticks = |i: usize| ((t[i] - t[i - 1]) / h).round().max(0.0);
    let mut out = Vec::with_capacity(n);
    if n == 0 {
        return out;
    }
    let d0 = if n > 1 && ticks(1) > 0.0 { (theta[1] - theta[0]) / ticks(1) } else { 0.0 };
    let mut z = Complex64::new(1.0 - a, 0.0) / (Complex64::cis(d0) - a) * Complex64::cis(theta[0]);
    out.push((z.im, z.re));
    for i in 1..n {
        let m = ticks(i);
        if m > 0.0 {
            let q = Complex64::cis((theta[i] - theta[i - 1]) / m);
            let an = a.powf(m);
            let sum = (Complex64::cis(theta[i] - theta[i - 1]) - an) / (q - a);
            z = z * an + Complex64::cis(theta[i - 1]) * sum * (1.0 - a);
        }
        out.push((z.im, z.re));
    }
    out
}

/// Shortest servo period considered, s (a 16 kHz servo).
pub const SERVO_PERIOD_MIN: f64 = 1.0 / 16_000.0;

/// The servo periods h (s) that the log times of the closed loop's following channels allow: a
/// controller logs on its own ticks, so every log interval is a whole number of ticks (within
/// 1 % of a tick). From the shortest interval Δ, h = Δ/m for m = 1, 2, … down to
/// [`SERVO_PERIOD_MIN`], longest first.
pub(crate) fn servo_period_candidates(st: &Stack) -> Vec<f64> {
    let intervals: Vec<f64> = closed_pairs(st)
        .into_iter()
        .flat_map(|(j, _)| st.chans[j].t.windows(2).map(|w| w[1] - w[0]).collect::<Vec<f64>>())
        .filter(|d| *d > 0.0)
        .collect();
    let Some(shortest) = intervals.iter().copied().reduce(f64::min) else { return Vec::new() };
    // index: a count, at most 1 024 candidates (a log interval of 64 ms at 16 kHz).
    let most = (shortest / SERVO_PERIOD_MIN + 1e-9).floor().min(1024.0) as usize;
    (1..=most)
        .map(|m| shortest / m as f64)
        .filter(|h| intervals.iter().all(|d| ((d / h) - (d / h).round()).abs() <= 0.01))
        .collect()
}

/// Whether any channel of `chans` is a following channel closed by the scale ([`close_loop`]).
pub(crate) fn has_closed_loop(chans: &[Channel]) -> bool {
    chans.iter().any(|c| matches!(c.encoder, Some(EncoderRole::Following { closed: true, .. })))
}

/// Indices of the following-error channels of a stack.
pub(crate) fn following_channels<'a>(st: &'a Stack) -> impl Iterator<Item = usize> + 'a {
    st.chans
        .iter()
        .enumerate()
        .filter(|(_, c)| matches!(c.encoder, Some(EncoderRole::Following { .. })))
        .map(|(j, _)| j)
}

/// The play signature of channel `c` for a backlash `b` (m), divided by b (so that its
/// coefficient is the backlash): p/b ∈ [−½, ½] from [`play`] driven by the motor reading (or, on a
/// lone encoder, by its own reading), times the channel's transmission sensitivity; None for a
/// channel that is not an encoder time series.
pub(crate) fn play_signature(c: &Channel, b: f64) -> Option<Vec<f64>> {
    let role = c.encoder.as_ref()?;
    let drive: &[f64] = match role {
        EncoderRole::Transmission { drive } => drive,
        EncoderRole::Following { .. } => &c.x,
    };
    let s = role.s_transmission();
    Some(play(drive, b).iter().map(|p| s * p / b).collect())
}

/// The encoder channels of one time-series run (module doc): with a linear scale and a motor
/// encoder, the transmission channel scale − motor and the following channel motor − command;
/// with one encoder, that encoder − command. Which encoder closes the loop comes from the
/// manifest's optional `closes_loop`, else from the data (the loop's encoder follows the command
/// smoothly: the smaller mean square of the second differences of encoder − command), said in a
/// note. Returns the channels; notes are appended to `notes`.
pub(crate) fn encoder_channels(
    set: &MeasurementSet,
    run: &crate::measurement::Run,
    x_cmd: &[f64],
    x_sigma: &[f64],
    t: &[f64],
    notes: &mut Vec<String>,
) -> Vec<Channel> {
    let RunData::TimeSeries { columns, .. } = &run.data else { return Vec::new() };
    let find = |kind: SensorKind| {
        columns.iter().find_map(|(n, v)| set.sensor(n).filter(|s| s.kind == kind).map(|s| (s, v.as_slice())))
    };
    let scale = find(SensorKind::EncoderLinear);
    let motor = find(SensorKind::EncoderRotary);
    let t0 = set.run_start(run);
    let times: Vec<f64> = t.iter().map(|v| t0 + v).collect();
    let vel: Vec<f64> = (0..x_cmd.len())
        .map(|i| {
            let (a, b) = if i == 0 { (0, 1.min(x_cmd.len() - 1)) } else { (i - 1, i) };
            if t[b] > t[a] {
                (x_cmd[b] - x_cmd[a]) / (t[b] - t[a])
            } else {
                0.0
            }
        })
        .collect();
    let d: Vec<f64> = vel.iter().map(|v| if *v < 0.0 { -1.0 } else { 1.0 }).collect();
    let channel = |sensor: String, kind: SensorKind, x: Vec<f64>, y: Vec<f64>, sigma: Option<f64>, role| Channel {
        run: run.name.clone(),
        sensor,
        kind,
        u: [1.0, 0.0, 0.0],
        r: [0.0; 3],
        x,
        d: d.clone(),
        cycle: vec![1; t.len()],
        t: times.clone(),
        v: vel.clone(),
        y,
        sigma,
        encoder: Some(role),
    };
    let minus = |a: &[f64], b: &[f64]| -> Vec<f64> { a.iter().zip(b).map(|(x, y)| x - y).collect() };
    match (scale, motor) {
        (Some((ss, sv)), Some((ms, mv))) => {
            let closed = if ss.closes_loop || ms.closes_loop {
                ss.closes_loop
            } else {
                let rough = |v: &[f64]| -> f64 {
                    let e = minus(v, x_cmd);
                    e.windows(3).map(|w| (w[2] - 2.0 * w[1] + w[0]).powi(2)).sum::<f64>() / e.len().max(1) as f64
                };
                let closed = rough(sv) < rough(mv);
                notes.push(format!(
                    "run `{}`: the manifest does not say which encoder closes the position loop (`closes_loop =                      true`); the data say `{}` (its reading follows the command more smoothly)",
                    run.name,
                    if closed { &ss.name } else { &ms.name }
                ));
                closed
            };
            let trans = minus(sv, mv);
            let sig = match (ss.sigma.filter(|v| *v > 0.0), ms.sigma.filter(|v| *v > 0.0)) {
                (Some(a), Some(b)) => Some(a.hypot(b)),
                _ => None,
            };
            vec![
                channel(
                    format!("{}-{}", ss.name, ms.name),
                    SensorKind::EncoderLinear,
                    sv.to_vec(),
                    trans,
                    sig,
                    EncoderRole::Transmission { drive: mv.to_vec() },
                ),
                channel(
                    format!("{}-x_cmd", ms.name),
                    SensorKind::EncoderRotary,
                    mv.to_vec(),
                    minus(mv, x_cmd),
                    ms.sigma.filter(|v| *v > 0.0),
                    EncoderRole::Following {
                        command: x_cmd.to_vec(),
                        command_sigma: x_sigma.to_vec(),
                        s_transmission: 0.0,
                        closed,
                    },
                ),
            ]
        }
        (Some((s, v)), None) | (None, Some((s, v))) => {
            let s_tr = if s.kind == SensorKind::EncoderLinear && !s.closes_loop { 1.0 } else { 0.0 };
            vec![channel(
                format!("{}-x_cmd", s.name),
                s.kind,
                v.to_vec(),
                minus(v, x_cmd),
                s.sigma.filter(|v| *v > 0.0),
                EncoderRole::Following {
                    command: x_cmd.to_vec(),
                    command_sigma: x_sigma.to_vec(),
                    s_transmission: s_tr,
                    closed: false,
                },
            )]
        }
        (None, None) => Vec::new(),
    }
}

/// The response x(t) of ẋ = kv·(u(t) − x) to an input `u` sampled at times `t` and linear between
/// samples, from the settled state of the first interval (x₀ = u₀ − s₀/kv, s₀ the first slope: the
/// lag of a cruise). Exact per interval of length h with slope s = (u₁ − u₀)/h:
///
/// ```text
/// x(h) = u₁ − s/kv + (x₀ − u₀ + s/kv)·e^{−kv·h}
/// ```
///
/// kv in 1/s, t in s; returns x at every sample (the same unit as u). Non-increasing times hold x.
pub fn first_order_lag(t: &[f64], u: &[f64], kv: f64) -> Vec<f64> {
    first_order_lag_each(t, &[u], kv).pop().unwrap_or_default()
}

/// [`first_order_lag`] of several inputs `us` on the clock `t`, in one pass over the samples (each
/// input's recursion independent of the others', so their latencies overlap): the same bits as
/// [`first_order_lag`] of each. Each input is taken to its first min(t, its length) values.
pub fn first_order_lag_each(t: &[f64], us: &[&[f64]], kv: f64) -> Vec<Vec<f64>> {
    clear_upper_state();
    let n = us.iter().map(|u| t.len().min(u.len())).max().unwrap_or(0);
    let mut out: Vec<Vec<f64>> = us.iter().map(|u| Vec::with_capacity(t.len().min(u.len()))).collect();
    if n == 0 {
        return out;
    }
    let mut xs: Vec<f64> = us
        .iter()
        .map(|u| {
            let s0 = if t.len().min(u.len()) > 1 && t[1] > t[0] { (u[1] - u[0]) / (t[1] - t[0]) } else { 0.0 };
            u.first().map_or(0.0, |u0| u0 - s0 / kv)
        })
        .collect();
    for ((o, x), u) in out.iter_mut().zip(&xs).zip(us) {
        if !u.is_empty() {
            o.push(*x);
        }
    }
    // e^{−kv·h} at a reference interval h_r, reused while |kv·(h − h_r)| < 1e-8 as
    // e^{−kv·h_r}·(1 − kv·(h − h_r)) (error below 1e-16, the rounding of an exp): a log sampled at
    // a fixed rate has one h up to the rounding of its time stamps, so one exp serves every sample.
    let mut reference = (f64::NAN, 0.0);
    for i in 1..n {
        let h = t[i] - t[i - 1];
        let decay = (h > 0.0).then(|| {
            let dh = kv * (h - reference.0);
            if dh.abs() < 1e-8 {
                reference.1 * (1.0 - dh)
            } else {
                reference = (h, (-kv * h).exp());
                reference.1
            }
        });
        for ((o, x), u) in out.iter_mut().zip(xs.iter_mut()).zip(us) {
            if i >= u.len() {
                continue;
            }
            if let Some(decay) = decay {
                let s = (u[i] - u[i - 1]) / h;
                *x = u[i] - s / kv + (*x - u[i - 1] + s / kv) * decay;
            }
            o.push(*x);
        }
    }
    out
}

/// The play of a transmission with backlash `b` (m) driven by `drive` (the motor position at
/// each sample, m): the table stands while the nut crosses the clearance, then is pushed. Returns
/// p = x_table − x_nut ∈ [−b/2, b/2] at each sample:
///
/// ```text
/// p_k = clamp(p_{k−1} − (drive_k − drive_{k−1}), −b/2, b/2),  p₀ = −sgn(first motion)·b/2
/// ```
///
/// (the table starts pushed from the side of the first motion). A step of ∓b/2 with the direction
/// of motion is the limit b → 0 of the shape; at a reversal the take-up lasts b/|v|.
pub fn play(drive: &[f64], b: f64) -> Vec<f64> {
    let half = 0.5 * b.abs();
    let first = drive.windows(2).map(|w| w[1] - w[0]).find(|d| *d != 0.0).unwrap_or(0.0);
    let mut p = -first.signum() * half;
    let mut out = Vec::with_capacity(drive.len());
    for (k, &x) in drive.iter().enumerate() {
        if k > 0 {
            // clamp: half = |b|/2 ≥ 0; b is finite (a model's value is range-checked when read, a
            // candidate's comes from a finite search bracket).
            p = (p - (x - drive[k - 1])).clamp(-half, half);
        }
        out.push(p);
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Several inputs lagged in one pass ([`first_order_lag_each`]) are the bits of each lagged
    /// alone, on a jittered clock with a repeated and a backward time stamp, inputs of 300, 1, 0 and
    /// 1 000 values (the last longer than the clock: cut to it).
    #[test]
    fn lags_in_one_pass_are_the_bits_of_each_alone() {
        let t: Vec<f64> = (0..800)
            .map(|i| match i {
                100 => 99.0 * 1.3e-3,
                200 => 198.9 * 1.3e-3,
                _ => i as f64 * 1.3e-3 + 2e-7 * ((i * 7919) % 13) as f64,
            })
            .collect();
        let u0: Vec<f64> = (0..300).map(|i| (i as f64 * 0.05).sin() * 1e-3).collect();
        let u3: Vec<f64> = (0..1000).map(|i| 1e-4 * i as f64 + (i as f64 * 0.31).cos() * 1e-6).collect();
        let us: [&[f64]; 4] = [&u0, &[2.5e-3], &[], &u3];
        let each = first_order_lag_each(&t, &us, 31.7);
        for (u, got) in us.iter().zip(&each) {
            let alone = first_order_lag(&t, u, 31.7);
            assert_eq!(got.len(), t.len().min(u.len()));
            assert!(got.iter().zip(&alone).all(|(a, b)| a.to_bits() == b.to_bits()));
            assert_eq!(got.len(), alone.len());
        }
    }

    /// A ramp u = v·t is followed with the lag v/kv from the start (settled), and a step response
    /// decays as e^{−kv·t} (hand-worked values).
    #[test]
    fn first_order_lag_ramp_and_step() {
        let t: Vec<f64> = (0..200).map(|i| i as f64 * 1e-3).collect();
        let u: Vec<f64> = t.iter().map(|t| 0.05 * t).collect();
        let x = first_order_lag(&t, &u, 25.0);
        for (xi, ui) in x.iter().zip(&u) {
            assert!((ui - xi - 0.05 / 25.0).abs() < 1e-15);
        }
        // A unit rise over one interval h from rest, then held: x(t₂) = 1 − (1 − e^{−kv·h})/(kv·h)
        // (the ramp's response), then x(t) = 1 + (x(t₂) − 1)·e^{−kv·(t − t₂)}.
        let (kv, h) = (25.0, 1e-3);
        let u2: Vec<f64> = (0..200).map(|i| if i < 2 { 0.0 } else { 1.0 }).collect();
        let x2 = first_order_lag(&t, &u2, kv);
        let at2 = 1.0 - (1.0 - (-kv * h).exp()) / (kv * h);
        let k = 100;
        let want = 1.0 + (at2 - 1.0) * (-kv * (t[k] - t[2])).exp();
        assert!((x2[k] - want).abs() < 1e-12, "{} vs {want}", x2[k]);
    }

    /// A closed loop run for `duration` s in ticks of `h` s from the motor at `xm` (m), each tick
    /// `step(t, x_m) → x_m`, logged every `every` ticks as its two channels (the transmission
    /// T(x_m) = `tr`, the following channel motor − `cmd`) at speed `v` (m/s); and the following
    /// channel's readings.
    fn closed_loop_log(
        (duration, h, every): (f64, f64, usize),
        v: f64,
        cmd: &dyn Fn(f64) -> f64,
        tr: &dyn Fn(f64) -> f64,
        mut xm: f64,
        step: &dyn Fn(f64, f64) -> f64,
    ) -> (Vec<Channel>, Vec<f64>) {
        let (mut t_log, mut x_log, mut m_log, mut tr_log) = (vec![], vec![], vec![], vec![]);
        for k in 0..(duration / h) as usize {
            let t = k as f64 * h;
            if k % every == 0 {
                t_log.push(t);
                x_log.push(cmd(t));
                m_log.push(xm);
                tr_log.push(tr(xm));
            }
            xm = step(t, xm);
        }
        let (t_log, x_log, m_log, tr_log) = (&t_log, &x_log, &m_log, &tr_log);
        let n = t_log.len();
        let chan = |y: Vec<f64>, role: EncoderRole| Channel {
            run: "r".into(),
            sensor: "s".into(),
            kind: SensorKind::EncoderLinear,
            u: [1.0, 0.0, 0.0],
            r: [0.0; 3],
            x: m_log.to_vec(),
            d: vec![1.0; n],
            cycle: vec![1; n],
            t: t_log.to_vec(),
            v: vec![v; n],
            y,
            sigma: None,
            encoder: Some(role),
        };
        let follow: Vec<f64> = m_log.iter().zip(x_log).map(|(a, b)| a - b).collect();
        let chans = vec![
            chan(tr_log.to_vec(), EncoderRole::Transmission { drive: m_log.to_vec() }),
            chan(
                follow.clone(),
                EncoderRole::Following {
                    command: x_log.to_vec(),
                    command_sigma: Vec::new(),
                    s_transmission: 0.0,
                    closed: true,
                },
            ),
        ];
        (chans, follow)
    }

    /// A closed loop's following channel is the lag of the command less the lag of the
    /// transmission: a P loop fed back from the scale (ẋ_m = kv·(x_cmd − x_m − T(x_m)), integrated
    /// here by RK4 at 20 µs, T a lead error of a few µm with a 7 mm wave) is predicted by
    /// following_error + close_loop of the transmission column to within 1 nm (the
    /// linear-between-samples input of [`first_order_lag`] at a 2 ms log: ≪ an encoder's noise),
    /// and the uncoupled prediction misses by the lag of T (≫ 10 nm).
    #[test]
    fn closed_loop_following_is_lag_less_lagged_transmission() {
        let kv = 31.7;
        let tr = |x: f64| 4e-6 * (x / 0.3) + 0.6e-6 * (std::f64::consts::TAU * x / 7e-3 + 0.4).sin();
        let cmd = |t: f64| 0.1 + 0.04 * t + 0.0002 * (2.1 * t).sin();
        // Settled start: x_m = cmd − v/kv − T (the loop holds the scale v/kv behind).
        let v0 = 0.04 + 0.0002 * 2.1;
        let mut xm = cmd(0.0) - v0 / kv - tr(cmd(0.0));
        for _ in 0..6 {
            xm = cmd(0.0) - v0 / kv - tr(xm);
        }
        let f = |t: f64, x: f64| kv * (cmd(t) - x - tr(x));
        let (h, every) = (20e-6, 100);
        let rk4 = |t: f64, xm: f64| {
            let k1 = f(t, xm);
            let k2 = f(t + h / 2.0, xm + h / 2.0 * k1);
            let k3 = f(t + h / 2.0, xm + h / 2.0 * k2);
            let k4 = f(t + h, xm + h * k3);
            xm + h / 6.0 * (k1 + 2.0 * k2 + 2.0 * k3 + k4)
        };
        let (chans, follow) = closed_loop_log((1.5, h, every), 0.04, &cmd, &tr, xm, &rk4);
        let tr_log = chans[0].y.clone();
        let n = tr_log.len();
        let st = Stack::new(&chans).with_loop(kv, 1.0);
        let lag = following_error(&chans[1], kv);
        let mut col: Vec<f64> = tr_log.iter().copied().chain(std::iter::repeat(0.0).take(n)).collect();
        close_loop(&st, &mut col);
        // The transmission channel is untouched.
        assert!(col[..n].iter().zip(&tr_log).all(|(a, b)| a == b));
        // Skip the first 0.5 s: first_order_lag starts settled on the first slope of its input,
        // and neither start is the loop's settled state on a wave of ω ≈ kv (≈ 0.5 µm off); the
        // difference decays as e^{−kv·t} (e^{−15.8} by 0.5 s; the model's start columns carry it).
        let skip = (0.5 / (h * every as f64)) as usize;
        let worst = (skip..n).map(|i| (follow[i] - lag[i] - col[n + i]).abs()).fold(0.0, f64::max);
        // 1 nm: the input linear between log samples misses the mean of a curved input by
        // Δt²/12·ẍ (0.3 nm for the command's 0.9 mm/s² and for T's ≈ 1 mm/s² at Δt = 2 ms).
        assert!(worst < 1e-9, "coupled prediction misses by {worst:e} m");
        let uncoupled = (skip..n).map(|i| (follow[i] - lag[i]).abs()).fold(0.0, f64::max);
        assert!(uncoupled > 1e-8, "uncoupled misses by only {uncoupled:e} m");
    }

    /// A sampled loop (x_{k+1} = x_k + kv·h·(u_k − x_k), u = command − T, h = 1 ms, the log every
    /// 2 ms) is predicted by the continuous law at kv' = −ln(1 − kv·h)/h with the lag scaled by
    /// g = kv'/kv on the command (the servo_lag gain) and on the transmission's path
    /// ([`Stack::loop_gain`]) to within 1 nm; with g = 1 on the transmission (a continuous loop)
    /// it misses by more than 10 nm (a 1 µm wave of 7 mm at 0.05 m/s: 7 Hz, near the loop's
    /// bandwidth). The Gauss–Newton step of [`gauss_newton_increment`] from g = 1 on the derivative of
    /// the loop's passage in g lands within 10⁻³ of g.
    #[test]
    fn a_sampled_loop_is_the_continuous_law_with_a_gain_on_the_lag() {
        let (kv, h, every): (f64, f64, usize) = (30.0, 1e-3, 2);
        let kv_eq = -(1.0 - kv * h).ln() / h;
        let g = kv_eq / kv;
        let tr = |x: f64| 2e-6 * (x / 0.3) + 1e-6 * (std::f64::consts::TAU * x / 7e-3 + 0.4).sin();
        let cmd = |t: f64| 0.1 + 0.05 * t;
        // Settled on the ramp: the error u − x is v/kv, u = cmd − T.
        let xm = cmd(0.0) - 0.05 / kv - tr(cmd(0.0));
        let sampled = |t: f64, xm: f64| xm + kv * h * (cmd(t) - xm - tr(xm));
        let (chans, follow) = closed_loop_log((1.2, h, every), 0.05, &cmd, &tr, xm, &sampled);
        let tr_log = chans[0].y.clone();
        let n = tr_log.len();
        let lag = following_error(&chans[1], kv_eq);
        let skip = (0.5 / (h * every as f64)) as usize;
        let worst_with = |gain: f64| {
            let st = Stack::new(&chans).with_loop(kv_eq, gain);
            let mut col: Vec<f64> = tr_log.iter().copied().chain(std::iter::repeat(0.0).take(n)).collect();
            close_loop(&st, &mut col);
            (skip..n).map(|i| (follow[i] - g * lag[i] - col[n + i]).abs()).fold(0.0, f64::max)
        };
        assert!(worst_with(g) < 1e-9, "sampled loop predicted within {:e} m", worst_with(g));
        assert!(worst_with(1.0) > 1e-8, "a continuous loop misses by only {:e} m", worst_with(1.0));
        // One Gauss–Newton step from g = 1 on the residual after the skip (the start carries the
        // settled-start difference of the other test).
        // The transmission is known here (no other parameter: z⊥ = z); its derivative in g is the
        // difference of its passages at g = 2 and g = 1.
        let through = |gain: f64| {
            let st = Stack::new(&chans).with_loop(kv_eq, gain);
            let mut col: Vec<f64> = tr_log.iter().copied().chain(std::iter::repeat(0.0).take(n)).collect();
            close_loop(&st, &mut col);
            col
        };
        let (col, col2) = (through(1.0), through(2.0));
        let z: Vec<f64> = col2.iter().zip(&col).map(|(a, b)| a - b).collect();
        let pred: Vec<f64> = (0..2 * n).map(|k| if k < n { tr_log[k] } else { g * lag[k - n] + col[k] }).collect();
        let y: Vec<f64> = tr_log.iter().chain(&follow).copied().collect();
        let resid: Vec<f64> = y.iter().zip(&pred).map(|(a, b)| a - b).collect();
        let w: Vec<f64> = (0..2 * n).map(|k| if k >= n + skip { 1.0 } else { 0.0 }).collect();
        let step = gauss_newton_increment(&z, &z, &resid, &w).expect("a closed loop");
        assert!((1.0 + step - g).abs() < 1e-3, "g {g}, step to {}", 1.0 + step);
    }

    /// The play: pushed at −b/2 going up, the table stands for b of motor travel after a reversal,
    /// then is pushed at +b/2.
    #[test]
    fn play_takes_up_the_clearance_at_a_reversal() {
        let b = 8e-6;
        let mut drive: Vec<f64> = (0..100).map(|k| k as f64 * 1e-6).collect();
        drive.extend((1..100).map(|k| 99e-6 - k as f64 * 1e-6));
        let p = play(&drive, b);
        assert!((p[50] + 4e-6).abs() < 1e-15);
        // Reversal at k = 99: the table stands (table = nut + p constant) for 8 µm of motor travel.
        for k in 100..=107 {
            let table = drive[k] + p[k];
            assert!((table - (drive[99] + p[99])).abs() < 1e-12, "k {k}");
        }
        assert!((p[150] - 4e-6).abs() < 1e-15);
    }

    /// [`wave_lag`] against the loop itself: ż = kv·(e^{iθ(t)} − z) integrated by RK4 on steps of
    /// 1/(40·the wave's highest frequency), θ = 2π·x(t)/p along a slow reversal x = D·sin(πt/T)
    /// after a lead-in at its start speed (the generator's reversal), over 40 random draws of kv
    /// (5–100 1/s), period (8–60 µm), D (0.5–3 mm), T (1–4 s) and log rate (250–1000 Hz). Between
    /// log samples [`wave_lag`] takes the phase linear in time; the reversal's curvature moves x by
    /// up to D·(π/T)²·h²/8 from that line (59 nm at 3 mm, 1 s, 250 Hz: 0.05 rad of an 8 µm wave, at
    /// the turn, where the loop follows the wave closely), so the error allowed is 1 % of the wave's
    /// unit amplitude (measured: 2.0e-3 at most). The steady response of the local speed
    /// (what `close_loop_wave` used before) must miss by more than 10 % on most draws: its error is
    /// the loop's transient as the speed sweeps through kv·p/2π.
    #[test]
    fn wave_lag_follows_the_loop_through_a_reversal() {
        use rand::{Rng, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(2008);
        let (mut worst, mut steady_misses) = (0.0_f64, 0);
        let draws = 40;
        for _ in 0..draws {
            let kv: f64 = rng.gen_range(5.0..100.0);
            let p: f64 = rng.gen_range(8e-6..60e-6);
            let (dd, tt): (f64, f64) = (rng.gen_range(0.5e-3..3e-3), rng.gen_range(1.0..4.0));
            let rate: f64 = rng.gen_range(250.0..1000.0);
            let w = std::f64::consts::PI / tt;
            let x = |t: f64| if t < 0.0 { dd * w * t } else { dd * (w * t).sin() };
            let th = |t: f64| TWO_PI * x(t) / p;
            let f_max = dd * w / p;
            let h = 1.0 / (40.0 * f_max);
            // Settled at the lead-in's speed 1 s before the log (5/kv at least).
            let lead = (5.0 / kv).max(1.0);
            let om0 = TWO_PI * dd * w / p;
            let d0 = kv * kv + om0 * om0;
            let (c0, s0) = (th(-lead).cos(), th(-lead).sin());
            let (a0, b0) = (kv * kv / d0, -kv * om0 / d0);
            let mut z = (a0 * c0 - b0 * s0, a0 * s0 + b0 * c0);
            let f = |t: f64, z: (f64, f64)| {
                let (c, s) = (th(t).cos(), th(t).sin());
                (kv * (c - z.0), kv * (s - z.1))
            };
            let (t_log, th_log): (Vec<f64>, Vec<f64>) =
                (0..(tt * rate) as usize).map(|i| i as f64 / rate).map(|t| (t, th(t))).unzip();
            let mut truth = Vec::with_capacity(t_log.len());
            let mut t = -lead;
            for &tl in &t_log {
                while t < tl - 1e-15 {
                    let hs = h.min(tl - t);
                    let k1 = f(t, z);
                    let k2 = f(t + hs / 2.0, (z.0 + hs / 2.0 * k1.0, z.1 + hs / 2.0 * k1.1));
                    let k3 = f(t + hs / 2.0, (z.0 + hs / 2.0 * k2.0, z.1 + hs / 2.0 * k2.1));
                    let k4 = f(t + hs, (z.0 + hs * k3.0, z.1 + hs * k3.1));
                    z.0 += hs / 6.0 * (k1.0 + 2.0 * k2.0 + 2.0 * k3.0 + k4.0);
                    z.1 += hs / 6.0 * (k1.1 + 2.0 * k2.1 + 2.0 * k3.1 + k4.1);
                    t += hs;
                }
                truth.push(z);
            }
            let got = wave_lag(&t_log, &th_log, kv);
            let err = got.iter().zip(&truth).map(|((im, re), z)| (im - z.1).hypot(re - z.0)).fold(0.0, f64::max);
            worst = worst.max(err);
            // The steady response of the local speed (central differences).
            let m = t_log.len();
            let steady = (0..m)
                .map(|i| {
                    let (i0, i1) = (i.saturating_sub(1), (i + 1).min(m - 1));
                    let om = (th_log[i1] - th_log[i0]) / (t_log[i1] - t_log[i0]);
                    let d = kv * kv + om * om;
                    let (a, b) = (kv * kv / d, -kv * om / d);
                    let (c, s) = (th_log[i].cos(), th_log[i].sin());
                    ((a * c - b * s) - truth[i].0).hypot((a * s + b * c) - truth[i].1)
                })
                .fold(0.0, f64::max);
            steady_misses += usize::from(steady > 0.1);
        }
        eprintln!("wave_lag: largest error {worst:.2e} of the unit wave; steady response off by > 10 % on {steady_misses}/{draws}");
        assert!(worst <= 0.01, "largest error {worst}");
        assert!(steady_misses >= draws / 2, "the steady response missed by > 10 % on only {steady_misses}/{draws}");
    }

    /// [`table_position`] inverts s = x_t + I(x_t) to 1e-14 m over 200 random waves up to the
    /// slope 2πA/p = 0.5 (far beyond a real scale's), and reads a known error at the table's position.
    #[test]
    fn table_position_inverts_the_scale_reading() {
        use rand::{Rng, SeedableRng};
        use vmt_sim::effects::InterpolationError;
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(11);
        for _ in 0..200 {
            let period = rng.gen_range(4e-6..100e-6);
            let slope = rng.gen_range(0.0..0.5);
            let ie = InterpolationError { period, amplitude: slope * period / TWO_PI, phase: rng.gen_range(-3.2..3.2) };
            let xt: f64 = rng.gen_range(-0.2..0.8);
            let s = xt + ie.value(xt);
            let got = table_position(&ie, s);
            assert!((got - xt).abs() <= 1e-14, "{got} vs {xt} (slope {slope})");
        }
    }

    /// [`wave_lag_sampled`] is the servo's own recursion: z_{k+1} = a·z_k + (1 − a)·e^{iθ(t_k)} run
    /// tick by tick from the settled state (a = e^{−kv·h}), over 30 random draws of kv (5–100 1/s),
    /// servo rate (1, 2, 4, 8 kHz), log decimation (1–12 ticks), speed (1–120 mm/s, so the wave is
    /// often far above the servo's Nyquist rate) and period (8–60 µm), at constant speed then a
    /// reversal (x quadratic in time: the phase is linear between log samples only at constant
    /// speed, so the reversal's part is checked at the log's own resolution, x linear between its
    /// samples, as the function takes it). Closed-form sums against the recursion: agreement to
    /// 1e-9 of the unit wave (rounding over up to 10⁵ ticks).
    #[test]
    fn wave_lag_sampled_is_the_servo_recursion() {
        use rand::{Rng, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(2000);
        for _ in 0..30 {
            let kv: f64 = rng.gen_range(5.0..100.0);
            let h = 1.0 / [1000.0, 2000.0, 4000.0, 8000.0][rng.gen_range(0..4)];
            let every: usize = rng.gen_range(1..=12);
            let v: f64 = rng.gen_range(1e-3..0.12);
            let p: f64 = rng.gen_range(8e-6..60e-6);
            let n_log = 400;
            // Log positions: a cruise, then a turn (x linear between log samples).
            let t: Vec<f64> = (0..n_log).map(|i| (i * every) as f64 * h).collect();
            let x: Vec<f64> = t
                .iter()
                .map(|&ti| if ti < t[n_log / 2] { v * ti } else { v * ti - 3.0 * v * (ti - t[n_log / 2]).powi(2) })
                .collect();
            let theta: Vec<f64> = x.iter().map(|x| TWO_PI * x / p).collect();
            let got = wave_lag_sampled(&t, &theta, kv, h);
            let a = (-kv * h).exp();
            let d0 = (theta[1] - theta[0]) / every as f64;
            let q0 = (d0.cos() - a, d0.sin());
            let g = ((1.0 - a) * q0.0 / (q0.0 * q0.0 + q0.1 * q0.1), -(1.0 - a) * q0.1 / (q0.0 * q0.0 + q0.1 * q0.1));
            let mut z = (g.0 * theta[0].cos() - g.1 * theta[0].sin(), g.0 * theta[0].sin() + g.1 * theta[0].cos());
            for i in 0..n_log {
                if i > 0 {
                    let step = (theta[i] - theta[i - 1]) / every as f64;
                    for k in 0..every {
                        let th = theta[i - 1] + k as f64 * step;
                        z = (a * z.0 + (1.0 - a) * th.cos(), a * z.1 + (1.0 - a) * th.sin());
                    }
                }
                let (im, re) = got[i];
                assert!((im - z.1).hypot(re - z.0) <= 1e-9, "sample {i}: {:?} vs {:?}", (re, im), z);
            }
        }
    }

    /// The servo periods a log allows: intervals of 2 ms and 9 ms on the ticks of a 1 kHz servo
    /// allow 1/k ms for k = 1 … 16 (2/m ms with m even, down to 1/16 ms), and never 2 ms (9 ms is
    /// not a whole number of them).
    #[test]
    fn servo_periods_divide_every_log_interval() {
        let n = 40;
        let times = |dt: f64| (0..n).map(|i| i as f64 * dt).collect::<Vec<f64>>();
        let chan = |t: Vec<f64>, role: EncoderRole, run: &str| Channel {
            run: run.into(),
            sensor: "s".into(),
            kind: SensorKind::EncoderLinear,
            u: [1.0, 0.0, 0.0],
            r: [0.0; 3],
            x: vec![0.0; n],
            d: vec![1.0; n],
            cycle: vec![1; n],
            t,
            v: vec![0.0; n],
            y: vec![0.0; n],
            sigma: None,
            encoder: Some(role),
        };
        let follow = || EncoderRole::Following {
            command: vec![0.0; n],
            command_sigma: Vec::new(),
            s_transmission: 0.0,
            closed: true,
        };
        let chans: Vec<Channel> = [("a", 2e-3), ("b", 9e-3)]
            .iter()
            .flat_map(|&(run, dt)| {
                [
                    chan(times(dt), EncoderRole::Transmission { drive: vec![0.0; n] }, run),
                    chan(times(dt), follow(), run),
                ]
            })
            .collect();
        let got = servo_period_candidates(&Stack::new(&chans));
        let want: Vec<f64> = (1..=16).map(|k| 2e-3 / (2 * k) as f64).collect();
        assert_eq!(got.len(), want.len(), "{got:?}");
        for (g, w) in got.iter().zip(&want) {
            assert!((g - w).abs() < 1e-15, "{got:?}");
        }
    }
}
