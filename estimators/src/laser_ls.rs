//! Laser line-set identification of geometric error motions (DESIGN.md §7; seeds 001 and 003).
//!
//! # Model (ISO 230-1 names, first order, small angles)
//!
//! A machine is a serial chain bed → axis 1 → axis 2 → … → tool point (for a 3-axis machine
//! bed → X → Y → Z → tool). Axis `j` (name J ∈ {X, Y, Z}, unit direction ê_J) carries six error
//! motions, functions of its position q_j: the translations E_j = [EXJ, EYJ, EZJ] (positioning
//! along J, straightness across it) and the angles ε_j = [EAJ, EBJ, ECJ] (about X, Y, Z).
//! A reading is taken at the measuring point `r` (m), fixed on the last body and measured from
//! the tool reference point (the point that sits at the machine origin when all q = 0).
//! The lever arm of axis j is the vector from its reference point to the measuring point,
//!
//! ```text
//!   ρ_j = Σ_{i>j} q_i ê_i + r                   (axes above j in the chain, plus the point offset)
//! ```
//!
//! so the angular errors of lower axes act through the full lever arm. Squareness: the first axis
//! of the chain is the primary reference, the second the secondary one; each later axis b is tilted
//! relative to each earlier axis a by a position-independent angle θ_ab about the third direction ĉ
//! (ISO 230-1 location errors): for the chain X → Y → Z these are
//! EC0Y (= `squareness_xy`, Y about Z), EB0Z (= `squareness_xz`, Z about Y), EA0Z (= `squareness_yz`,
//! Z about X). The volumetric error at the measuring point is
//!
//! ```text
//!   δ = Σ_j [ E_j(q_j) + ε_j(q_j) × ρ_j ] + Σ_{a<b} θ_ab (ĉ × ê_b) q_b
//!   for X→Y→Z:  δ_sq = ( −EC0Y·q_y + EB0Z·q_z,  −EA0Z·q_z,  0 )
//! ```
//!
//! and a laser reading (linear, straightness or vector/diagonal) is `u · δ + offset_line`, with
//! `u` the unit beam direction and `offset_line` the unknown zero of the laser line the reading
//! belongs to (interferometers measure displacement from where they were zeroed). Everything is
//! linear in the parameters, so one weighted least-squares problem covers every measurement design.
//!
//! # Gauge (what the readings can never see) and the reporting convention
//!
//! With one unknown zero per line, constant parts of the error motions and a rigid rotation of the
//! whole machine frame leave every reading unchanged. They are fixed by the ISO 230-1 reporting
//! convention, applied only inside the null space of the data (it never moves the fit):
//! * positioning and angular error motions are reported relative to their value at the axis
//!   `reference_position` (the position where the laser was zeroed);
//! * straightness is reported about its least-squares reference line over `report_positions`;
//! * squareness is the angle between the least-squares lines of the axes' paths at the reference
//!   positions, i.e. θ'_ab = θ_ab + σ_ab·[ê_a·dδ_b + ê_b·dδ_a], where dδ are the direction changes of
//!   the paths from the straightness slopes, the other squareness terms and the angles of the axes
//!   a ≤ i < b at their reference positions, and σ_ab = (ĉ × ê_b)·ê_a = ±1.
//!
//! Whatever stays undetermined after that is reported by name in `Identification::unobservable`.

use faer::Mat;
use serde::{Deserialize, Serialize};
use thiserror::Error;

/// Errors of the laser line-set identification. Messages say what was expected.
#[derive(Debug, Error, Clone, PartialEq)]
pub enum LaserLsError {
    /// The input does not fit the documented contract.
    #[error("laser line-set identification: {0}")]
    InvalidInput(String),
    /// The SVD did not converge (should not happen with finite input).
    #[error("laser line-set identification: SVD did not converge")]
    Svd,
}

/// A position (m) outside the domain [lo, hi] (m) of a motion's basis: its nodes or its Legendre range.
#[derive(Debug, Error, Clone, Copy, PartialEq)]
#[error("position {q} m is outside the {domain} [{lo}, {hi}] m")]
struct OutsideBasis {
    q: f64,
    domain: &'static str,
    lo: f64,
    hi: f64,
}

/// A reading whose axis position lies outside the basis of one of the axis's motions.
#[derive(Debug, Error, Clone, PartialEq)]
#[error("axis {axis:?} ({motion}): {source}")]
struct OutsideMotion {
    axis: Axis,
    motion: String,
    source: OutsideBasis,
}

fn bad<T>(msg: String) -> Result<T, LaserLsError> {
    Err(LaserLsError::InvalidInput(msg))
}

/// Name of a linear axis, which is also its nominal direction in the machine frame: vmt's one [`Axis`]
/// (crate `vmt-core`, which the simulator's chain uses too).
pub use vmt_core::axis::Axis;

const TRANS: [char; 3] = ['X', 'Y', 'Z'];
const ROT: [char; 3] = ['A', 'B', 'C'];

/// ISO 230-1 name of error motion `component` (0..3 translations along X, Y, Z; 3..6 rotations
/// about X, Y, Z) of axis `axis`, e.g. (X, 4) → "EBX".
pub fn motion_name(axis: Axis, component: usize) -> String {
    let c = if component < 3 { TRANS[component] } else { ROT[component.min(5) - 3] };
    format!("E{}{}", c, axis.iso_letter())
}

fn unit(i: usize) -> [f64; 3] {
    let mut e = [0.0; 3];
    e[i] = 1.0;
    e
}
fn cross(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]
}
fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

/// How one error motion is parameterised as a function of its axis position q (m).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub enum Basis {
    /// Not modelled: held at zero (e.g. known to be negligible).
    Fixed,
    /// Values at the nodes (m, strictly increasing, at least two), piecewise-linear interpolation
    /// between them: f(q) = f_k + (f_{k+1} − f_k)(q − q_k)/(q_{k+1} − q_k).
    Nodes(Vec<f64>),
    /// Legendre polynomials P_0 … P_order of t = 2(q − lo)/(hi − lo) − 1 ∈ [−1, 1]
    /// (well conditioned compared with monomials).
    Legendre {
        /// Highest degree (≤ 15).
        order: usize,
        /// Lower end of the position range (m).
        lo: f64,
        /// Upper end of the position range (m).
        hi: f64,
    },
}

impl Basis {
    fn len(&self) -> usize {
        match self {
            Basis::Fixed => 0,
            Basis::Nodes(n) => n.len(),
            Basis::Legendre { order, .. } => order + 1,
        }
    }

    fn validate(&self, what: &str) -> Result<(), LaserLsError> {
        match self {
            Basis::Fixed => Ok(()),
            Basis::Nodes(n) => {
                if n.len() < 2 {
                    return bad(format!("{what}: needs at least 2 nodes, got {}", n.len()));
                }
                for w in n.windows(2) {
                    if !(w[0].is_finite() && w[1].is_finite()) || w[1] <= w[0] {
                        return bad(format!(
                            "{what}: nodes must be finite and strictly increasing, got {} after {}",
                            w[1], w[0]
                        ));
                    }
                }
                Ok(())
            }
            Basis::Legendre { order, lo, hi } => {
                if !(lo.is_finite() && hi.is_finite()) || hi <= lo {
                    return bad(format!("{what}: Legendre range needs finite lo < hi, got [{lo}, {hi}]"));
                }
                if *order > 15 {
                    return bad(format!("{what}: Legendre order must be ≤ 15, got {order}"));
                }
                Ok(())
            }
        }
    }

    /// Values of the basis functions at q; error if q is outside the basis domain.
    fn eval(&self, q: f64, out: &mut Vec<f64>) -> Result<(), OutsideBasis> {
        out.clear();
        match self {
            Basis::Fixed => Ok(()),
            Basis::Nodes(n) => {
                // index: at least two finite, strictly increasing nodes (Basis::validate), so k ≤ len − 2 below.
                let tol = 1e-9 * (n[n.len() - 1] - n[0]);
                if !(q >= n[0] - tol && q <= n[n.len() - 1] + tol) {
                    return Err(OutsideBasis { q, domain: "nodes", lo: n[0], hi: n[n.len() - 1] });
                }
                out.resize(n.len(), 0.0);
                // clamp: nodes finite and strictly increasing, at least two (Basis::validate).
                let qc = q.clamp(n[0], n[n.len() - 1]);
                let k = match n.iter().position(|&v| v > qc) {
                    Some(0) => 0,
                    Some(k) => k - 1,
                    None => n.len() - 2,
                };
                let t = (qc - n[k]) / (n[k + 1] - n[k]);
                out[k] = 1.0 - t;
                out[k + 1] = t;
                Ok(())
            }
            Basis::Legendre { order, lo, hi } => {
                let tol = 1e-9 * (hi - lo);
                if !(q >= lo - tol && q <= hi + tol) {
                    return Err(OutsideBasis { q, domain: "range", lo: *lo, hi: *hi });
                }
                let t = 2.0 * (q - lo) / (hi - lo) - 1.0;
                out.push(1.0);
                if *order >= 1 {
                    out.push(t);
                }
                for n in 1..*order {
                    let nf = n as f64;
                    let p = ((2.0 * nf + 1.0) * t * out[n] - nf * out[n - 1]) / (nf + 1.0);
                    out.push(p);
                }
                Ok(())
            }
        }
    }
}

/// One axis of the serial chain and the parameterisation of its six error motions.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct AxisModel {
    /// Axis name = nominal direction.
    pub name: Axis,
    /// Reference position (m): positioning and angles are reported relative to their value here,
    /// and squareness is defined with the other axes at their reference positions.
    pub reference_position: f64,
    /// Bases of [E{X}J, E{Y}J, E{Z}J, EAJ, EBJ, ECJ] (ISO 230-1 order: translations, then angles).
    pub motions: [Basis; 6],
    /// Positions (m) where the profiles are reported; the straightness least-squares reference
    /// line is taken over them (at least two distinct values).
    pub report_positions: Vec<f64>,
}

impl AxisModel {
    /// All six error motions as values at `nodes` (piecewise linear), reference position = first
    /// node, profiles reported at the nodes.
    pub fn with_nodes(name: Axis, nodes: &[f64]) -> AxisModel {
        let b = Basis::Nodes(nodes.to_vec());
        AxisModel {
            name,
            reference_position: nodes.first().copied().unwrap_or(0.0),
            motions: [b.clone(), b.clone(), b.clone(), b.clone(), b.clone(), b],
            report_positions: nodes.to_vec(),
        }
    }
}

/// The parameterisation of the whole chain.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Model {
    /// Axes in chain order from the bed to the tool (1 to 3, distinct names).
    pub axes: Vec<AxisModel>,
    /// Whether to estimate the squareness angles θ_ab between every pair of axes.
    pub squareness: bool,
}

/// One laser reading: reading = beam · δ(q, r) + offset of its line (m).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Reading {
    /// Axis positions (m), one per axis of the model in chain order.
    pub q: Vec<f64>,
    /// Measuring point r (m) on the last body, from the tool reference point.
    pub point: [f64; 3],
    /// Unit beam direction (machine frame); |u| must be 1 within 1e-6.
    pub direction: [f64; 3],
    /// Reading (m).
    pub value: f64,
    /// 1-σ noise of the reading (m), > 0.
    pub sigma: f64,
    /// Laser line (setup) the reading belongs to: readings of one line share one unknown zero.
    /// `None`: an absolute reading without offset.
    pub line: Option<usize>,
}

/// Where the noise level used for the standard errors comes from.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub enum SigmaMode {
    /// Trust the readings' `sigma`: Cov = (AᵀWA)⁺.
    Given,
    /// Scale by the a-posteriori variance factor s² = Σ (r_i/σ_i)² / (m − rank).
    FromResiduals,
}

/// Options of [`identify`].
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct IdOptions {
    /// Noise level for the standard errors.
    pub sigma_mode: SigmaMode,
    /// Singular values below `rank_rtol · s_max` of the column-scaled, weighted matrix count as zero.
    pub rank_rtol: f64,
}

impl Default for IdOptions {
    fn default() -> Self {
        IdOptions { sigma_mode: SigmaMode::Given, rank_rtol: 1e-9 }
    }
}

/// Estimated profile of one error motion.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ProfileEstimate {
    /// ISO 230-1 name, e.g. "EBX".
    pub name: String,
    /// Axis it belongs to.
    pub axis: Axis,
    /// 0..3: translation along X, Y, Z; 3..6: rotation about X, Y, Z.
    pub component: usize,
    /// Positions (m).
    pub positions: Vec<f64>,
    /// Values (m or rad) in the reporting convention of the module doc.
    pub values: Vec<f64>,
    /// 1-σ standard errors (m or rad); `None` where the value is not observable.
    pub std_errors: Vec<Option<f64>>,
}

/// Estimated squareness angle.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SquarenessEstimate {
    /// ISO 230-1 name, e.g. "EC0Y".
    pub name: String,
    /// vmt effect name, e.g. "squareness_xy".
    pub effect: String,
    /// Angle (rad) between the least-squares lines (module doc).
    pub value: f64,
    /// 1-σ standard error (rad); `None` if not observable.
    pub std_error: Option<f64>,
}

/// Result of [`identify`].
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Identification {
    /// Names of the parameters (e.g. `EBX[3]` = 4th basis coefficient, "EC0Y", "offset line 2").
    pub param_names: Vec<String>,
    /// Parameter values (SI) in the reporting gauge.
    pub params: Vec<f64>,
    /// 1-σ standard errors of the parameters; `None` for unobservable ones.
    pub std_errors: Vec<Option<f64>>,
    /// Number of readings.
    pub n_readings: usize,
    /// Numerical rank of the weighted, column-scaled observation matrix.
    pub rank: usize,
    /// Condition number s_max/s_min over the retained singular values (column-scaled matrix).
    pub condition: f64,
    /// Number of gauge directions fixed by the reporting convention.
    pub gauge_fixed: usize,
    /// a-posteriori variance factor Σ(r_i/σ_i)²/(m − rank) (≈ 1 when the given σ are right).
    pub variance_factor: f64,
    /// Noise scale used for the standard errors: 1 (Given) or √variance_factor.
    pub sigma_scale: f64,
    /// Human-readable statements of what the readings cannot determine.
    pub unobservable: Vec<String>,
    /// Profiles of the modelled error motions.
    pub profiles: Vec<ProfileEstimate>,
    /// Squareness angles (if modelled).
    pub squareness: Vec<SquarenessEstimate>,
}

impl Identification {
    /// The profile called `name` ("EXX", "EBY", …), if modelled.
    pub fn profile(&self, name: &str) -> Option<&ProfileEstimate> {
        self.profiles.iter().find(|p| p.name == name)
    }
    /// The squareness estimate called `name` ("EC0Y" or "squareness_xy"), if modelled.
    pub fn squareness(&self, name: &str) -> Option<&SquarenessEstimate> {
        self.squareness.iter().find(|s| s.name == name || s.effect == name)
    }
}

/// Column layout of the parameter vector.
struct Layout {
    /// (start, len) of motion (axis j, component k) = blocks[j][k].
    blocks: Vec<[(usize, usize); 6]>,
    /// (a, b, c, column): squareness of axis b vs axis a about direction index c.
    squareness: Vec<(usize, usize, usize, usize)>,
    /// line id → column.
    lines: Vec<(usize, usize)>,
    n: usize,
}

fn validate_model(model: &Model) -> Result<(), LaserLsError> {
    if model.axes.is_empty() || model.axes.len() > 3 {
        return bad(format!("model needs 1 to 3 axes, got {}", model.axes.len()));
    }
    for (j, ax) in model.axes.iter().enumerate() {
        for (i, other) in model.axes.iter().enumerate().take(j) {
            if other.name == ax.name {
                return bad(format!("axis {:?} appears twice in the chain (positions {i} and {j})", ax.name));
            }
        }
        if !ax.reference_position.is_finite() {
            return bad(format!("axis {:?}: reference position must be finite", ax.name));
        }
        if ax.report_positions.iter().any(|p| !p.is_finite()) {
            return bad(format!("axis {:?}: report positions must be finite", ax.name));
        }
        let mut rp = ax.report_positions.clone();
        rp.sort_by(|a, b| a.total_cmp(b));
        rp.dedup();
        if rp.len() < 2 {
            return bad(format!(
                "axis {:?}: needs at least 2 distinct report positions (straightness reference line), got {}",
                ax.name,
                rp.len()
            ));
        }
        let mut buf = Vec::new();
        for (k, b) in ax.motions.iter().enumerate() {
            let what = motion_name(ax.name, k);
            b.validate(&what)?;
            if let Err(e) = b.eval(ax.reference_position, &mut buf) {
                return bad(format!("{what}: reference {e}"));
            }
            for &p in &ax.report_positions {
                if let Err(e) = b.eval(p, &mut buf) {
                    return bad(format!("{what}: report {e}"));
                }
            }
        }
    }
    Ok(())
}

fn validate_readings(readings: &[Reading], n_axes: usize) -> Result<(), LaserLsError> {
    if readings.is_empty() {
        return bad("no readings given".into());
    }
    for (i, r) in readings.iter().enumerate() {
        if r.q.len() != n_axes {
            return bad(format!("reading {i}: expected {n_axes} axis positions (one per axis), got {}", r.q.len()));
        }
        let vs = [r.value, r.sigma];
        let mut all = r.q.iter().chain(r.point.iter()).chain(r.direction.iter()).chain(vs.iter());
        if all.any(|v| !v.is_finite()) {
            return bad(format!("reading {i}: NaN or infinite value"));
        }
        let nu = dot(r.direction, r.direction).sqrt();
        if (nu - 1.0).abs() > 1e-6 {
            return bad(format!("reading {i}: beam direction must be a unit vector, |u| = {nu}"));
        }
        if r.sigma <= 0.0 {
            return bad(format!("reading {i}: sigma must be > 0 m, got {}", r.sigma));
        }
    }
    Ok(())
}

fn build_layout(model: &Model, readings: &[Reading]) -> Layout {
    let mut n = 0;
    let mut blocks = Vec::new();
    for ax in &model.axes {
        let mut b = [(0, 0); 6];
        for (k, basis) in ax.motions.iter().enumerate() {
            b[k] = (n, basis.len());
            n += basis.len();
        }
        blocks.push(b);
    }
    let mut squareness = Vec::new();
    if model.squareness {
        for b in 0..model.axes.len() {
            for a in 0..b {
                let c = 3 - model.axes[a].name.index() - model.axes[b].name.index();
                squareness.push((a, b, c, n));
                n += 1;
            }
        }
    }
    let mut lines: Vec<(usize, usize)> = Vec::new();
    for r in readings {
        if let Some(l) = r.line {
            if !lines.iter().any(|(id, _)| *id == l) {
                lines.push((l, n));
                n += 1;
            }
        }
    }
    Layout { blocks, squareness, lines, n }
}

/// Unweighted observation row of one reading (length `layout.n`).
fn observation_row(model: &Model, layout: &Layout, r: &Reading, buf: &mut Vec<f64>) -> Result<Vec<f64>, OutsideMotion> {
    let mut row = vec![0.0; layout.n];
    let na = model.axes.len();
    for j in 0..na {
        // lever arm ρ_j = Σ_{i>j} q_i ê_i + r
        let mut rho = r.point;
        for i in (j + 1)..na {
            rho[model.axes[i].name.index()] += r.q[i];
        }
        let rxu = cross(rho, r.direction);
        for k in 0..6 {
            let (start, len) = layout.blocks[j][k];
            if len == 0 {
                continue;
            }
            model.axes[j].motions[k].eval(r.q[j], buf).map_err(|source| OutsideMotion {
                axis: model.axes[j].name,
                motion: motion_name(model.axes[j].name, k),
                source,
            })?;
            // translation: u_k; rotation: (ê_k × ρ)·u = ê_k·(ρ × u)
            let s = if k < 3 { r.direction[k] } else { rxu[k - 3] };
            for (t, v) in buf.iter().enumerate() {
                row[start + t] += s * v;
            }
        }
    }
    for &(_, b, c, col) in &layout.squareness {
        let eb = model.axes[b].name.index();
        row[col] += dot(cross(unit(c), unit(eb)), r.direction) * r.q[b];
    }
    if let Some(l) = r.line {
        let col = layout.lines.iter().find(|(id, _)| *id == l).map(|x| x.1);
        if let Some(col) = col {
            row[col] = 1.0;
        }
    }
    Ok(row)
}

/// A reported group of functionals: one error motion of an axis, or one squareness.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Group {
    /// Error motion `component` of `axis` (0..3 translations along X, Y, Z; 3..6 rotations about
    /// them), as [`motion_name`] numbers them.
    Motion { axis: Axis, component: usize },
    /// A squareness: the angle about direction `about` (0..3: X, Y, Z) of `axis`, the later axis
    /// of the pair.
    Squareness { about: usize, axis: Axis },
}

impl Group {
    /// The ISO 230-1 name: `EBX` for the pitch of X, `EC0Y` for the squareness of Y to X.
    fn name(self) -> String {
        match self {
            Group::Motion { axis, component } => motion_name(axis, component),
            Group::Squareness { about, axis } => format!("E{}0{}", ROT[about], axis.iso_letter()),
        }
    }

    /// True for an angle (a rotation or a squareness, rad), false for a translation (m).
    fn is_angle(self) -> bool {
        match self {
            Group::Motion { component, .. } => component >= 3,
            Group::Squareness { .. } => true,
        }
    }
}

/// A reported quantity as a linear functional of the parameters.
struct Functional {
    group: usize,
    coef: Vec<f64>,
}

/// Reporting functionals (profiles at report positions and squareness) and gauge rows.
fn functionals(model: &Model, layout: &Layout) -> (Vec<Functional>, Vec<Vec<f64>>, Vec<Group>) {
    let mut out = Vec::new();
    let mut gauge = Vec::new();
    let mut groups = Vec::new();
    let mut buf = Vec::new();
    let n = layout.n;
    // slope functional of motion (j, k) over the report positions
    let ls = |j: usize, k: usize, buf: &mut Vec<f64>| -> (Vec<f64>, Vec<f64>, f64) {
        let ax = &model.axes[j];
        let (start, _) = layout.blocks[j][k];
        let pos = &ax.report_positions;
        let m = pos.len() as f64;
        let mean_p = pos.iter().sum::<f64>() / m;
        let sxx: f64 = pos.iter().map(|p| (p - mean_p) * (p - mean_p)).sum();
        let mut mean = vec![0.0; n];
        let mut slope = vec![0.0; n];
        for &p in pos {
            ax.motions[k].eval(p, buf).expect("validated");
            for (t, v) in buf.iter().enumerate() {
                mean[start + t] += v / m;
                slope[start + t] += (p - mean_p) * v / sxx;
            }
        }
        (mean, slope, mean_p)
    };
    for (j, ax) in model.axes.iter().enumerate() {
        for k in 0..6 {
            let (start, len) = layout.blocks[j][k];
            if len == 0 {
                continue;
            }
            let group = groups.len();
            groups.push(Group::Motion { axis: ax.name, component: k });
            let straightness = k < 3 && k != ax.name.index();
            let mut refrow = vec![0.0; n];
            let (mean, slope, mean_p) = ls(j, k, &mut buf);
            if straightness {
                gauge.push(mean.clone());
                gauge.push(slope.clone());
            } else {
                ax.motions[k].eval(ax.reference_position, &mut buf).expect("validated");
                for (t, v) in buf.iter().enumerate() {
                    refrow[start + t] = *v;
                }
                gauge.push(refrow.clone());
            }
            for &p in &ax.report_positions {
                let mut coef = vec![0.0; n];
                ax.motions[k].eval(p, &mut buf).expect("validated");
                for (t, v) in buf.iter().enumerate() {
                    coef[start + t] = *v;
                }
                if straightness {
                    for i in 0..n {
                        coef[i] -= mean[i] + (p - mean_p) * slope[i];
                    }
                } else {
                    for i in 0..n {
                        coef[i] -= refrow[i];
                    }
                }
                out.push(Functional { group, coef });
            }
        }
    }
    // squareness: θ'_ab = θ_ab + σ_ab [ê_a·dδ_b + ê_b·dδ_a]
    for &(a, b, c, col) in &layout.squareness {
        let group = groups.len();
        let na = model.axes[a].name;
        let nb = model.axes[b].name;
        groups.push(Group::Squareness { about: c, axis: nb });
        let ea = unit(na.index());
        let eb = unit(nb.index());
        let sigma = dot(cross(unit(c), eb), ea);
        let mut inner = vec![0.0; n];
        // squareness terms on b (seen along ê_a) and on a (seen along ê_b)
        for &(_, b2, c2, col2) in &layout.squareness {
            if b2 == b {
                inner[col2] += dot(cross(unit(c2), eb), ea);
            }
            if b2 == a {
                inner[col2] += dot(cross(unit(c2), ea), eb);
            }
        }
        // straightness slopes: component a of axis b, component b of axis a
        for (axis, comp) in [(b, na.index()), (a, nb.index())] {
            if layout.blocks[axis][comp].1 > 0 {
                let (_, slope, _) = ls(axis, comp, &mut buf);
                for i in 0..n {
                    inner[i] += slope[i];
                }
            }
        }
        // angles of axes a ≤ i < b at their reference positions: ε_i·(ê_b × ê_a)
        let bxa = cross(eb, ea);
        for i in a..b {
            for (kk, &b) in bxa.iter().enumerate() {
                let (start, len) = layout.blocks[i][3 + kk];
                if len == 0 || b == 0.0 {
                    continue;
                }
                model.axes[i].motions[3 + kk].eval(model.axes[i].reference_position, &mut buf).expect("validated");
                for (t, v) in buf.iter().enumerate() {
                    inner[start + t] += b * v;
                }
            }
        }
        // θ_ab's own term: inner[col] = σ_ab, so coef[col] = σ_ab² = 1.
        let coef: Vec<f64> = inner.iter().map(|v| sigma * v).collect();
        debug_assert!((coef[col] - 1.0).abs() < 1e-12);
        out.push(Functional { group, coef });
    }
    (out, gauge, groups)
}

/// A thin SVD: (U (rows × n), singular values s (n), V (n × n)).
type Svd = (Mat<f64>, Vec<f64>, Mat<f64>);

/// SVD with at least as many rows as columns (zero rows appended if needed).
fn svd_padded(a: &Mat<f64>) -> Result<Svd, LaserLsError> {
    let (m, n) = (a.nrows(), a.ncols());
    let padded;
    let src = if m < n {
        padded = Mat::<f64>::from_fn(n, n, |i, j| if i < m { a[(i, j)] } else { 0.0 });
        &padded
    } else {
        a
    };
    let svd = src.thin_svd().map_err(|_| LaserLsError::Svd)?;
    let s: Vec<f64> = (0..n).map(|i| svd.S().column_vector()[i]).collect();
    Ok((svd.U().to_owned(), s, svd.V().to_owned()))
}

/// Identifies the error motions (and squareness) from laser readings by weighted least squares.
///
/// Follows DESIGN.md §7: each reading is `u·δ(q, r) + offset_line` with δ the first-order
/// volumetric error of the module doc, linear in the parameters p, so with W = diag(1/σ_i²)
/// the estimate is p̂ = argmin ‖W^{1/2}(A p − y)‖². The columns of W^{1/2}A are scaled to unit
/// norm (m and rad, any lever arm) and decomposed by the SVD (faer); rank = number of singular
/// values above `rank_rtol·s_max`; condition = s_max/s_min of the retained ones. Gauge
/// directions (module doc) are fixed inside the null space; the parameter covariance is
/// Cov = s²·P (AᵀWA)⁺ Pᵀ (P the gauge projection, s² = 1 or the a-posteriori factor).
/// Profiles are reported at each axis' `report_positions` with σ from Cov. Undetermined
/// error motions, or combinations of them, are named in `unobservable`.
///
/// # Example
///
/// One X axis, only its positioning error EXX modelled (values at four nodes); one laser line along X
/// read at the nodes going out and back. The truth is a 10 µm/m scale error, so EXX, reported relative
/// to the reference position 0 m, is 3 µm at 0.3 m.
///
/// ```rust
/// use vmt_estimators::laser_ls::{identify, AxisModel, Axis, Basis, IdOptions, Model, Reading};
/// let nodes = [0.0, 0.1, 0.2, 0.3]; // m
/// let mut axis = AxisModel::with_nodes(Axis::X, &nodes);
/// for m in &mut axis.motions[1..] {
///     *m = Basis::Fixed; // EYX … ECX not modelled
/// }
/// let model = Model { axes: vec![axis], squareness: false };
/// let reading = |q: f64| Reading {
///     q: vec![q],
///     point: [0.0; 3],
///     direction: [1.0, 0.0, 0.0],
///     value: 1e-5 * q + 0.7e-6, // m: the error plus the laser's unknown zero
///     sigma: 1e-7,              // m
///     line: Some(0),
/// };
/// let readings: Vec<Reading> = nodes.iter().chain(nodes.iter().rev()).map(|&q| reading(q)).collect();
/// let id = identify(&readings, &model, &IdOptions::default()).unwrap();
/// let exx = id.profile("EXX").unwrap();
/// assert_eq!(exx.positions, nodes);
/// for (q, e) in exx.positions.iter().zip(&exx.values) {
///     assert!((e - 1e-5 * q).abs() < 1e-12, "EXX({q} m) = {e} m");
/// }
/// ```
pub fn identify(readings: &[Reading], model: &Model, opts: &IdOptions) -> Result<Identification, LaserLsError> {
    validate_model(model)?;
    validate_readings(readings, model.axes.len())?;
    if !(opts.rank_rtol > 0.0 && opts.rank_rtol < 1.0) {
        return bad(format!("rank_rtol must be in (0, 1), got {}", opts.rank_rtol));
    }
    let layout = build_layout(model, readings);
    let n = layout.n;
    let m = readings.len();
    if n == 0 {
        return bad("the model has no parameters (all error motions Fixed)".into());
    }
    // weighted observation matrix
    let mut buf = Vec::new();
    let mut a = Mat::<f64>::zeros(m, n);
    let mut y = vec![0.0; m];
    for (i, r) in readings.iter().enumerate() {
        let row = observation_row(model, &layout, r, &mut buf)
            .map_err(|e| LaserLsError::InvalidInput(format!("reading {i}: {e}")))?;
        for (jj, v) in row.iter().enumerate() {
            a[(i, jj)] = v / r.sigma;
        }
        y[i] = r.value / r.sigma;
    }
    // column scaling: A_s = A D, p = D p_s
    // (a column no reading touches keeps the median scale of the others, so that the
    // observability tests compare like with like)
    let mut d = vec![0.0; n];
    for jj in 0..n {
        let nrm: f64 = (0..m).map(|i| a[(i, jj)] * a[(i, jj)]).sum::<f64>().sqrt();
        if nrm > 0.0 {
            d[jj] = 1.0 / nrm;
            for i in 0..m {
                a[(i, jj)] *= d[jj];
            }
        }
    }
    let mut nz: Vec<f64> = d.iter().copied().filter(|&x| x > 0.0).collect();
    nz.sort_by(|x, y| x.total_cmp(y));
    let typical = nz.get(nz.len() / 2).copied().unwrap_or(1.0);
    for x in d.iter_mut() {
        if *x == 0.0 {
            *x = typical;
        }
    }
    let (u, s, v) = svd_padded(&a)?;
    let smax = s[0];
    let rank = if smax > 0.0 { s.iter().filter(|&&x| x > opts.rank_rtol * smax).count() } else { 0 };
    let condition = if rank > 0 { smax / s[rank - 1] } else { f64::INFINITY };
    // minimum-norm solution in scaled coordinates
    let mut ps = vec![0.0; n];
    for t in 0..rank {
        let c: f64 = (0..m).map(|i| u[(i, t)] * y[i]).sum::<f64>() / s[t];
        for jj in 0..n {
            ps[jj] += v[(jj, t)] * c;
        }
    }
    // residuals
    let mut rss = 0.0;
    for i in 0..m {
        let fit: f64 = (0..n).map(|jj| a[(i, jj)] * ps[jj]).sum();
        rss += (y[i] - fit).powi(2);
    }
    let dof = m.saturating_sub(rank);
    let variance_factor = if dof > 0 { rss / dof as f64 } else { f64::NAN };
    let sigma_scale = match opts.sigma_mode {
        SigmaMode::Given => 1.0,
        SigmaMode::FromResiduals => {
            if dof == 0 {
                return bad(format!(
                    "cannot estimate σ from residuals: {m} readings and rank {rank} leave no degrees of freedom"
                ));
            }
            variance_factor.sqrt()
        }
    };
    // L = V_r S_r⁻¹ (scaled coordinates), null space N_s
    let nnull = n - rank;
    let mut l = Mat::<f64>::from_fn(n, rank, |jj, t| v[(jj, t)] / s[t]);
    let nul = Mat::<f64>::from_fn(n, nnull, |jj, t| v[(jj, rank + t)]);
    // gauge rows in scaled coordinates, normalised
    let (funcs, gauge, groups) = functionals(model, &layout);
    let nc = gauge.len();
    let cs = Mat::<f64>::from_fn(nc, n, |i, jj| gauge[i][jj] * d[jj]);
    let cs = {
        let mut c2 = cs;
        for i in 0..nc {
            let nr: f64 = (0..n).map(|jj| c2[(i, jj)].powi(2)).sum::<f64>().sqrt();
            if nr > 0.0 {
                for jj in 0..n {
                    c2[(i, jj)] /= nr;
                }
            }
        }
        c2
    };
    let mut free = Mat::<f64>::zeros(n, 0);
    let mut gauge_fixed = 0;
    if nnull > 0 {
        // CN and its pseudo-inverse
        let cn = &cs * &nul; // nc × nnull
        let (cu, csv, cv) = svd_padded(&cn)?;
        let cmax = csv.first().copied().unwrap_or(0.0);
        let crank = csv.iter().filter(|&&x| cmax > 0.0 && x > 1e-8 * cmax).count();
        gauge_fixed = crank;
        // (CN)⁺ x = Σ_t v_t (u_tᵀ x)/s_t
        let pinv_apply = |x: &[f64]| -> Vec<f64> {
            let mut w = vec![0.0; nnull];
            for t in 0..crank {
                let c: f64 = (0..nc).map(|i| cu[(i, t)] * x[i]).sum::<f64>() / csv[t];
                for q in 0..nnull {
                    w[q] += cv[(q, t)] * c;
                }
            }
            w
        };
        // p_s ← p_s − N (CN)⁺ C p_s
        let cp: Vec<f64> = (0..nc).map(|i| (0..n).map(|jj| cs[(i, jj)] * ps[jj]).sum()).collect();
        let w = pinv_apply(&cp);
        for jj in 0..n {
            ps[jj] -= (0..nnull).map(|q| nul[(jj, q)] * w[q]).sum::<f64>();
        }
        // L ← L − N (CN)⁺ C L
        let cl = &cs * &l; // nc × rank
        for t in 0..rank {
            let col: Vec<f64> = (0..nc).map(|i| cl[(i, t)]).collect();
            let w = pinv_apply(&col);
            for jj in 0..n {
                l[(jj, t)] -= (0..nnull).map(|q| nul[(jj, q)] * w[q]).sum::<f64>();
            }
        }
        // free null directions: N · null(CN)
        let nfree = nnull - crank;
        free = Mat::<f64>::from_fn(n, nfree, |jj, f| (0..nnull).map(|q| nul[(jj, q)] * cv[(q, crank + f)]).sum());
    }
    let nfree = free.ncols();
    // parameter values and standard errors
    let params: Vec<f64> = (0..n).map(|jj| ps[jj] * d[jj]).collect();
    let std_errors: Vec<Option<f64>> = (0..n)
        .map(|jj| {
            let fr: f64 = (0..nfree).map(|f| free[(jj, f)].powi(2)).sum::<f64>().sqrt();
            if fr > 1e-7 {
                None
            } else {
                let sl: f64 = (0..rank).map(|t| l[(jj, t)].powi(2)).sum::<f64>().sqrt();
                Some(sigma_scale * sl * d[jj])
            }
        })
        .collect();
    // functionals: values, std, observability
    let mut fvals = Vec::with_capacity(funcs.len());
    let mut gn_rows: Vec<Vec<f64>> = Vec::with_capacity(funcs.len());
    for f in &funcs {
        let gs: Vec<f64> = (0..n).map(|jj| f.coef[jj] * d[jj]).collect();
        let gnorm = gs.iter().map(|x| x * x).sum::<f64>().sqrt();
        let val: f64 = (0..n).map(|jj| f.coef[jj] * params[jj]).sum();
        let gn: Vec<f64> =
            (0..nfree).map(|ff| (0..n).map(|jj| gs[jj] * free[(jj, ff)]).sum::<f64>() / gnorm.max(1e-300)).collect();
        let unobs = gn.iter().map(|x| x * x).sum::<f64>().sqrt() > 1e-7;
        let sd = if unobs || gnorm == 0.0 {
            if gnorm == 0.0 {
                Some(0.0)
            } else {
                None
            }
        } else {
            let sl: f64 =
                (0..rank).map(|t| (0..n).map(|jj| gs[jj] * l[(jj, t)]).sum::<f64>().powi(2)).sum::<f64>().sqrt();
            Some(sigma_scale * sl)
        };
        fvals.push((val, sd));
        gn_rows.push(gn);
    }
    // profiles
    let mut profiles = Vec::new();
    let mut squareness = Vec::new();
    let mut fi = 0;
    for ax in &model.axes {
        for k in 0..6 {
            if ax.motions[k].len() == 0 {
                continue;
            }
            let np = ax.report_positions.len();
            let vals = &fvals[fi..fi + np];
            profiles.push(ProfileEstimate {
                name: motion_name(ax.name, k),
                axis: ax.name,
                component: k,
                positions: ax.report_positions.clone(),
                values: vals.iter().map(|x| x.0).collect(),
                std_errors: vals.iter().map(|x| x.1).collect(),
            });
            fi += np;
        }
    }
    for &(a, b, _, _) in &layout.squareness {
        let (val, sd) = fvals[fi];
        let mut pair = [model.axes[a].name.iso_letter(), model.axes[b].name.iso_letter()];
        pair.sort();
        squareness.push(SquarenessEstimate {
            name: groups[funcs[fi].group].name(),
            effect: format!("squareness_{}{}", pair[0].to_ascii_lowercase(), pair[1].to_ascii_lowercase()),
            value: val,
            std_error: sd,
        });
        fi += 1;
    }
    let unobservable = describe_unobservable(model, &layout, readings, &funcs, &gn_rows, &groups, &free, &d);
    let mut param_names = vec![String::new(); n];
    for (j, ax) in model.axes.iter().enumerate() {
        for k in 0..6 {
            let (start, len) = layout.blocks[j][k];
            for t in 0..len {
                param_names[start + t] = format!("{}[{t}]", motion_name(ax.name, k));
            }
        }
    }
    for (i, &(_, _, _, col)) in layout.squareness.iter().enumerate() {
        param_names[col] = squareness[i].name.clone();
    }
    for &(id, col) in &layout.lines {
        param_names[col] = format!("offset line {id}");
    }
    Ok(Identification {
        param_names,
        params,
        std_errors,
        n_readings: m,
        rank,
        condition,
        gauge_fixed,
        variance_factor,
        sigma_scale,
        unobservable,
        profiles,
        squareness,
    })
}

/// Numerical rank of a set of rows (each of the same length) by SVD.
fn rows_rank(rows: &[&Vec<f64>], tol: f64) -> usize {
    if rows.is_empty() || rows[0].is_empty() {
        return 0;
    }
    let a = Mat::<f64>::from_fn(rows.len(), rows[0].len(), |i, j| rows[i][j]);
    match svd_padded(&a) {
        Ok((_, s, _)) => s.iter().filter(|&&x| x > tol).count(),
        Err(_) => 0,
    }
}

#[allow(clippy::too_many_arguments)]
fn describe_unobservable(
    model: &Model,
    layout: &Layout,
    readings: &[Reading],
    funcs: &[Functional],
    gn_rows: &[Vec<f64>],
    groups: &[Group],
    free: &Mat<f64>,
    d: &[f64],
) -> Vec<String> {
    let ng = groups.len();
    let nfree = free.ncols();
    if nfree == 0 {
        return Vec::new();
    }
    let tol = 1e-7;
    let rows_of = |g: usize| -> Vec<&Vec<f64>> {
        funcs.iter().zip(gn_rows).filter(|(f, _)| f.group == g).map(|(_, r)| r).collect()
    };
    let dims: Vec<usize> = (0..ng).map(|g| rows_rank(&rows_of(g), tol)).collect();
    // union-find over coupled groups
    let mut parent: Vec<usize> = (0..ng).collect();
    fn find(p: &mut [usize], i: usize) -> usize {
        let mut i = i;
        while p[i] != i {
            p[i] = p[p[i]];
            i = p[i];
        }
        i
    }
    // Two groups are coupled when some undetermined direction moves both: the spans of their
    // rows (their images of the free null space) are not orthogonal.
    let significant = |g: usize| -> Vec<Vec<f64>> {
        rows_of(g)
            .into_iter()
            .filter_map(|r| {
                let nr = r.iter().map(|x| x * x).sum::<f64>().sqrt();
                (nr > tol).then(|| r.iter().map(|x| x / nr).collect())
            })
            .collect()
    };
    let sig: Vec<Vec<Vec<f64>>> = (0..ng).map(significant).collect();
    for g1 in 0..ng {
        if dims[g1] == 0 {
            continue;
        }
        for g2 in (g1 + 1)..ng {
            if dims[g2] == 0 {
                continue;
            }
            let coupled = sig[g1]
                .iter()
                .any(|a| sig[g2].iter().any(|b| a.iter().zip(b).map(|(x, y)| x * y).sum::<f64>().abs() > 1e-6));
            if coupled {
                let (a, b) = (find(&mut parent, g1), find(&mut parent, g2));
                parent[a] = b;
            }
        }
    }
    let mut msgs = Vec::new();
    let mut done = vec![false; ng];
    for g in 0..ng {
        if dims[g] == 0 || done[g] {
            continue;
        }
        let root = find(&mut parent, g);
        let members: Vec<usize> = (0..ng).filter(|&h| dims[h] > 0 && find(&mut parent, h) == root).collect();
        for &h in &members {
            done[h] = true;
        }
        // representative undetermined direction: the strongest null combination of the members
        let mut rows = Vec::new();
        for &h in &members {
            rows.extend(rows_of(h));
        }
        let mat = Mat::<f64>::from_fn(rows.len(), nfree, |i, j| rows[i][j]);
        let example = svd_padded(&mat).ok().map(|(_, _, v)| {
            let w: Vec<f64> = (0..nfree).map(|f| v[(f, 0)]).collect();
            // the null vector in parameter units, evaluated through each member's functionals
            let nvec: Vec<f64> =
                (0..d.len()).map(|jj| (0..nfree).map(|f| free[(jj, f)] * w[f]).sum::<f64>() * d[jj]).collect();
            let rms: Vec<f64> = members
                .iter()
                .map(|&h| {
                    let vals: Vec<f64> = funcs
                        .iter()
                        .filter(|f| f.group == h)
                        .map(|f| f.coef.iter().zip(&nvec).map(|(c, x)| c * x).sum::<f64>())
                        .collect();
                    (vals.iter().map(|x| x * x).sum::<f64>() / vals.len().max(1) as f64).sqrt()
                })
                .collect();
            rms
        });
        let names: Vec<String> = members.iter().map(|&h| groups[h].name()).collect();
        // reported degrees of freedom of a group: rank of its functionals (scaled coordinates)
        let reported_dofs = |h: usize| -> usize {
            let scaled: Vec<Vec<f64>> = funcs
                .iter()
                .filter(|f| f.group == h)
                .map(|f| {
                    let v: Vec<f64> = f.coef.iter().zip(d).map(|(c, s)| c * s).collect();
                    let nr = v.iter().map(|x| x * x).sum::<f64>().sqrt().max(1e-300);
                    v.iter().map(|x| x / nr).collect()
                })
                .collect();
            rows_rank(&scaled.iter().collect::<Vec<_>>(), 1e-9)
        };
        let total_dofs: usize = members.iter().map(|&h| reported_dofs(h)).sum();
        let undetermined = rows_rank(&rows, tol);
        let mut msg = if members.len() == 1 {
            let h = members[0];
            let full = reported_dofs(h);
            if dims[h] >= full {
                format!("{} is not observable with these readings", names[0])
            } else {
                format!(
                    "{} is only partly observable: {} of its {} reported values cannot be determined",
                    names[0], dims[h], full
                )
            }
        } else {
            let list = match names.len() {
                2 => format!("{} and {}", names[0], names[1]),
                _ => format!("{} and {}", names[..names.len() - 1].join(", "), names[names.len() - 1]),
            };
            format!(
                "{list} are confounded with these readings: {undetermined} combination(s) of their {total_dofs} reported values cannot be determined"
            )
        };
        if let Some(rms) = example {
            let mx = rms.iter().cloned().fold(0.0, f64::max);
            if mx > 0.0 && members.len() > 1 {
                let parts: Vec<String> = members
                    .iter()
                    .zip(&rms)
                    .filter(|(_, r)| **r > 1e-3 * mx)
                    .map(|(&h, r)| {
                        let unit = if groups[h].is_angle() { "µrad" } else { "µm" };
                        format!("{:.3} {unit} RMS of {}", r / mx, groups[h].name())
                    })
                    .collect();
                msg.push_str(&format!(
                    " (e.g. changing {} together leaves every reading unchanged)",
                    parts.join(" with ")
                ));
            }
        }
        // lever-arm hint for angular error motions
        for &h in &members {
            if let Some(hint) = lever_hint(model, layout, readings, groups[h]) {
                msg.push_str(&format!("; {hint}"));
            }
        }
        msgs.push(msg);
    }
    msgs
}

/// For an angular error motion: which lever arms (ρ × u)_k the readings give it, per beam direction.
fn lever_hint(model: &Model, _layout: &Layout, readings: &[Reading], group: Group) -> Option<String> {
    let (axis, k) = match group {
        Group::Motion { axis, component: c @ 3.. } => (axis, c - 3),
        Group::Motion { .. } | Group::Squareness { .. } => return None,
    };
    let j = model.axes.iter().position(|a| a.name == axis)?;
    let na = model.axes.len();
    // distinct lever values per distinct beam direction
    let mut per_dir: Vec<([f64; 3], Vec<f64>)> = Vec::new();
    for r in readings {
        let mut rho = r.point;
        for i in (j + 1)..na {
            rho[model.axes[i].name.index()] += r.q[i];
        }
        // index: k = component − 3 is 0..3, the motions' components being 0..6 (`functionals`).
        let lev = cross(rho, r.direction)[k];
        let entry = per_dir.iter_mut().find(|(u, _)| (0..3).all(|c| (u[c] - r.direction[c]).abs() < 1e-9));
        match entry {
            Some((_, vals)) => {
                if !vals.iter().any(|v| (v - lev).abs() < 1e-9) {
                    vals.push(lev)
                }
            }
            None => per_dir.push((r.direction, vec![lev])),
        }
    }
    let single: Vec<String> = per_dir
        .iter()
        .filter(|(_, vals)| vals.len() == 1)
        .map(|(u, vals)| format!("beam ({:.3}, {:.3}, {:.3}): lever {:.4} m", u[0], u[1], u[2], vals[0]))
        .collect();
    if single.len() == per_dir.len() {
        Some(format!(
            "{}'s lever arm (point × beam)·ê_{} has a single value per beam direction [{}], so its effect cannot be told from the translations and line offsets",
            group.name(),
            ['x', 'y', 'z'][k],
            single.join("; ")
        ))
    } else {
        None
    }
}

// ---------------------------------------------------------------------------------------------
// Measurement designs
// ---------------------------------------------------------------------------------------------

/// One planned laser reading (no value yet): axis positions, measuring point, beam direction,
/// line id and a label such as "δx@P1".
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct PlannedReading {
    /// Axis positions (m), one per axis of the chain.
    pub q: Vec<f64>,
    /// Measuring point r (m) from the tool reference point.
    pub point: [f64; 3],
    /// Unit beam direction.
    pub direction: [f64; 3],
    /// Line (laser setup) id.
    pub line: usize,
    /// Human-readable label of the line.
    pub label: String,
}

/// Turns a plan and its measured values (m) into readings with noise σ (m).
pub fn readings_from_plan(plan: &[PlannedReading], values: &[f64], sigma: f64) -> Result<Vec<Reading>, LaserLsError> {
    if plan.len() != values.len() {
        return bad(format!("expected one value per planned reading ({}), got {}", plan.len(), values.len()));
    }
    Ok(plan
        .iter()
        .zip(values)
        .map(|(p, &v)| Reading {
            q: p.q.clone(),
            point: p.point,
            direction: p.direction,
            value: v,
            sigma,
            line: Some(p.line),
        })
        .collect())
}

fn check_positions(positions: &[f64]) -> Result<(), LaserLsError> {
    if positions.len() < 2 {
        return bad(format!("needs at least 2 positions, got {}", positions.len()));
    }
    for w in positions.windows(2) {
        if !(w[0].is_finite() && w[1].is_finite()) || w[1] <= w[0] {
            return bad(format!("positions must be finite and strictly increasing, got {} after {}", w[1], w[0]));
        }
    }
    Ok(())
}

/// Seed 003's 9-line (three-point) design for one X axis: δx at P1, P2, P3, δy at P1, P2 and
/// δz at P1 (six lines; the seed's "9 lines" counts the 3 × 3 = 9 component readings it sets up
/// over the points), at every position of `positions` (seed: every 100 mm), `runs` runs, each
/// forward and, if `bidirectional`, backward (the seed: "linear–bidirectional", 3 runs).
/// Points (m) are on the moving body, from the axis reference point. Line ids: 0 δx@P1,
/// 1 δx@P2, 2 δx@P3, 3 δy@P1, 4 δy@P2, 5 δz@P1.
pub fn nine_line_plan(
    points: &[[f64; 3]; 3],
    positions: &[f64],
    runs: usize,
    bidirectional: bool,
) -> Result<Vec<PlannedReading>, LaserLsError> {
    check_positions(positions)?;
    if runs == 0 {
        return bad("needs at least one run".into());
    }
    if points.iter().flatten().any(|v| !v.is_finite()) {
        return bad("measuring points must be finite".into());
    }
    let lines: [(usize, usize, &str); 6] =
        [(0, 0, "δx@P1"), (1, 0, "δx@P2"), (2, 0, "δx@P3"), (0, 1, "δy@P1"), (1, 1, "δy@P2"), (0, 2, "δz@P1")];
    let mut plan = Vec::new();
    for (id, &(p, dir, label)) in lines.iter().enumerate() {
        for _ in 0..runs {
            let mut order: Vec<f64> = positions.to_vec();
            if bidirectional {
                order.extend(positions.iter().rev());
            }
            for &x in &order {
                plan.push(PlannedReading {
                    q: vec![x],
                    point: points[p],
                    direction: unit(dir),
                    line: id,
                    label: label.to_string(),
                });
            }
        }
    }
    Ok(plan)
}

/// Closed-form 9-line solution at one position (seed 003's relation matrix solved explicitly):
/// with P_i = (x_i, y_i, z_i) and readings relative to the reference position,
/// ```text
///   δx_i = EXX + z_i·EBX − y_i·ECX          (i = 1, 2, 3)
///   δy_i = EYX + x_i·ECX − z_i·EAX          (i = 1, 2)
///   δz_1 = EZX + y_1·EAX − x_1·EBX
/// ```
/// EBX, ECX from the differences of the δx (D = (y2−y1)(z3−z1) − (z2−z1)(y3−y1)),
/// EAX from δy_1 − δy_2, then EXX, EYX, EZX. Returns [EXX, EYX, EZX, EAX, EBX, ECX] (m, rad).
pub fn nine_line_closed_form(points: &[[f64; 3]; 3], m: [f64; 6]) -> Result<[f64; 6], LaserLsError> {
    let [p1, p2, p3] = *points;
    let det = (p2[1] - p1[1]) * (p3[2] - p1[2]) - (p2[2] - p1[2]) * (p3[1] - p1[1]);
    let dz = p2[2] - p1[2];
    let span = points.iter().flat_map(|p| p.iter()).fold(0.0f64, |a, v| a.max(v.abs())).max(1e-3);
    if det.abs() < 1e-9 * span * span {
        return bad(format!(
            "the three δx points must not be collinear in the Y–Z plane (2·area = {det} m²): EBX and ECX cannot be separated"
        ));
    }
    if dz.abs() < 1e-9 * span {
        return bad("the two δy points P1, P2 must be at different heights: EAX cannot be separated".into());
    }
    let (dm2, dm3) = (m[1] - m[0], m[2] - m[0]);
    let ebx = ((p2[1] - p1[1]) * dm3 - (p3[1] - p1[1]) * dm2) / det;
    let ecx = ((p2[2] - p1[2]) * dm3 - (p3[2] - p1[2]) * dm2) / det;
    let exx = m[0] - p1[2] * ebx + p1[1] * ecx;
    let eax = (m[3] - m[4] - (p1[0] - p2[0]) * ecx) / dz;
    let eyx = m[3] - p1[0] * ecx + p1[2] * eax;
    let ezx = m[5] - p1[1] * eax + p1[0] * ebx;
    Ok([exx, eyx, ezx, eax, ebx, ecx])
}

/// D-optimality criterion of a 9-line role assignment: det(HᵀH) of the 6 × 6 per-position
/// observation matrix H of [`nine_line_closed_form`], which equals (D·(z2 − z1))² (m⁴·…;
/// only ratios matter: a change of units multiplies every candidate by the same factor).
pub fn nine_line_d_criterion(points: &[[f64; 3]; 3]) -> f64 {
    let [p1, p2, p3] = *points;
    let det = (p2[1] - p1[1]) * (p3[2] - p1[2]) - (p2[2] - p1[2]) * (p3[1] - p1[1]);
    (det * (p2[2] - p1[2])).powi(2)
}

/// D-optimal choice of the three 9-line points among candidates (m): exhaustive search over
/// every ordered triple (P1 carries δx, δy, δz; P2 δx, δy; P3 δx) maximising
/// [`nine_line_d_criterion`] = det of the information matrix per position. Returns the indices.
pub fn d_optimal_nine_line(candidates: &[[f64; 3]]) -> Result<[usize; 3], LaserLsError> {
    let m = candidates.len();
    if m < 3 {
        return bad(format!("needs at least 3 candidate points, got {m}"));
    }
    if m > 200 {
        return bad(format!("exhaustive search limited to 200 candidates, got {m}"));
    }
    if candidates.iter().flatten().any(|v| !v.is_finite()) {
        return bad("candidate points must be finite".into());
    }
    let mut best = (f64::NEG_INFINITY, [0, 1, 2]);
    for i in 0..m {
        for j in 0..m {
            for k in 0..m {
                if i == j || j == k || i == k {
                    continue;
                }
                let c = nine_line_d_criterion(&[candidates[i], candidates[j], candidates[k]]);
                if c > best.0 {
                    best = (c, [i, j, k]);
                }
            }
        }
    }
    if best.0 <= 0.0 {
        return bad("every triple of candidates is degenerate (collinear or equal heights)".into());
    }
    Ok(best.1)
}

/// Result of [`kmeans`].
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct KMeans {
    /// Cluster of each sample.
    pub labels: Vec<usize>,
    /// Centroids in the z-score normalised feature space.
    pub centroids: Vec<Vec<f64>>,
    /// Lloyd iterations performed.
    pub iterations: usize,
    /// Sum of squared distances to the centroids (normalised space).
    pub inertia: f64,
    /// For each cluster, the sample nearest to its centroid (the representative).
    pub representatives: Vec<usize>,
}

/// SplitMix64: small deterministic generator for the seeded initialisation.
fn splitmix(state: &mut u64) -> u64 {
    *state = state.wrapping_add(0x9E37_79B9_7F4A_7C15);
    let mut z = *state;
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

/// k-means clustering as in seed 003 (steps S4-1 … S4-7): z-score normalisation of every feature
/// x' = (x − mean)/std (features with zero spread are set to 0), k initial centres drawn from the
/// samples by a seeded generator, then Lloyd iterations (assign by Euclidean distance
/// d(p'_i, p'_j) = √Σ_n (p'_in − p'_jn)², move centres to the means) until the labels stop
/// changing or `max_iter`. Deterministic for a given seed.
pub fn kmeans(features: &[Vec<f64>], k: usize, seed: u64, max_iter: usize) -> Result<KMeans, LaserLsError> {
    let m = features.len();
    if k == 0 || m < k {
        return bad(format!("k-means needs 1 ≤ k ≤ number of samples, got k = {k}, {m} samples"));
    }
    let dim = features[0].len();
    if dim == 0 || features.iter().any(|f| f.len() != dim) {
        return bad("k-means: every sample needs the same, non-zero number of features".into());
    }
    if features.iter().flatten().any(|v| !v.is_finite()) {
        return bad("k-means: features must be finite".into());
    }
    let mut z = vec![vec![0.0; dim]; m];
    for c in 0..dim {
        let mean = features.iter().map(|f| f[c]).sum::<f64>() / m as f64;
        let sd = (features.iter().map(|f| (f[c] - mean).powi(2)).sum::<f64>() / m as f64).sqrt();
        for i in 0..m {
            z[i][c] = if sd > 0.0 { (features[i][c] - mean) / sd } else { 0.0 };
        }
    }
    let mut state = seed;
    let mut chosen: Vec<usize> = Vec::new();
    while chosen.len() < k {
        // index: a remainder of m, so i < m (m ≥ 1 samples, checked above).
        let i = (splitmix(&mut state) % m as u64) as usize;
        if !chosen.contains(&i) {
            chosen.push(i);
        }
    }
    let mut centroids: Vec<Vec<f64>> = chosen.iter().map(|&i| z[i].clone()).collect();
    let dist2 = |a: &[f64], b: &[f64]| a.iter().zip(b).map(|(x, y)| (x - y).powi(2)).sum::<f64>();
    let mut labels = vec![usize::MAX; m];
    let mut iterations = 0;
    for _ in 0..max_iter.max(1) {
        iterations += 1;
        let mut changed = false;
        for i in 0..m {
            let mut best = (f64::INFINITY, 0);
            for (c, cen) in centroids.iter().enumerate() {
                let dd = dist2(&z[i], cen);
                if dd < best.0 {
                    best = (dd, c);
                }
            }
            if labels[i] != best.1 {
                labels[i] = best.1;
                changed = true;
            }
        }
        for (c, cen) in centroids.iter_mut().enumerate() {
            let members: Vec<usize> = (0..m).filter(|&i| labels[i] == c).collect();
            if members.is_empty() {
                continue; // keep an empty cluster's centre where it was
            }
            for d in 0..dim {
                cen[d] = members.iter().map(|&i| z[i][d]).sum::<f64>() / members.len() as f64;
            }
        }
        if !changed {
            break;
        }
    }
    let inertia = (0..m).map(|i| dist2(&z[i], &centroids[labels[i]])).sum();
    let representatives = (0..k)
        .map(|c| {
            (0..m)
                .min_by(|&a, &b| {
                    let pa = if labels[a] == c { 0.0 } else { 1e300 };
                    let pb = if labels[b] == c { 0.0 } else { 1e300 };
                    (dist2(&z[a], &centroids[c]) + pa).total_cmp(&(dist2(&z[b], &centroids[c]) + pb))
                })
                .unwrap_or(0)
        })
        .collect();
    Ok(KMeans { labels, centroids, iterations, inertia, representatives })
}

/// Seed 003's point selection: k-means (k = 3) on the 9-dimensional feature vectors
/// [x, y, z, σxx, σyx, σzx, εxx, εyx, εzx] of the candidate points (positions and per-point
/// error summaries supplied by the caller), one representative per cluster (the sample nearest
/// the centroid: the seed leaves this choice to "engineering practice"), then the three
/// representatives are given the 9-line roles (P1, P2, P3) that maximise
/// [`nine_line_d_criterion`] (the seed does not say; this isolates the choice of points).
pub fn kmeans_nine_line(
    candidates: &[[f64; 3]],
    error_features: &[[f64; 6]],
    seed: u64,
) -> Result<[usize; 3], LaserLsError> {
    if candidates.len() != error_features.len() {
        return bad(format!(
            "one feature row per candidate expected: {} candidates, {} rows",
            candidates.len(),
            error_features.len()
        ));
    }
    let feats: Vec<Vec<f64>> =
        candidates.iter().zip(error_features).map(|(p, e)| p.iter().chain(e.iter()).copied().collect()).collect();
    let km = kmeans(&feats, 3, seed, 100)?;
    let r = &km.representatives;
    let perms = [[0, 1, 2], [0, 2, 1], [1, 0, 2], [1, 2, 0], [2, 0, 1], [2, 1, 0]];
    let mut best = (f64::NEG_INFINITY, [r[0], r[1], r[2]]);
    for p in perms {
        let idx = [r[p[0]], r[p[1]], r[p[2]]];
        let c = nine_line_d_criterion(&[candidates[idx[0]], candidates[idx[1]], candidates[idx[2]]]);
        if c > best.0 {
            best = (c, idx);
        }
    }
    Ok(best.1)
}

// ---------------------------------------------------------------------------------------------
// Seed 001: laser Doppler line set for a 3-axis machine
// ---------------------------------------------------------------------------------------------

/// Geometry of seed 001's measurement plan (chain X → Y → Z → tool).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Seed001Plan {
    /// Node positions (m) of X, Y, Z (each strictly increasing, starting at the reference).
    pub positions: [Vec<f64>; 3],
    /// Offsets x0, y0, z0 (m) of the offset lines 4–9.
    pub offsets: [f64; 3],
    /// Tool-point offsets (m): the four body diagonals are measured in vector (step) mode once
    /// per offset. The roll of the top axis (ECZ) is only seen through a tool offset, and it
    /// separates from the straightness of Z only with two different offsets.
    pub diagonal_tool_offsets: Vec<[f64; 3]>,
    /// Whether to add the four body diagonals (the vector method) after lines 1–9.
    pub diagonals: bool,
}

/// Seed 001's line set. Lines 1–3: positioning along X, Y, Z from the origin (eq. 9). Lines 4–9:
/// linear readings along an axis at an offset (eqs. 10–11): 4 X at q_y = y0 (ECX), 5 Y at
/// q_z = z0 (EAY), 6 Z with tool offset x0 (EBZ), 7 X at q_z = z0 (EBX), 8 Y with tool offset x0
/// (ECY), 9 Z with tool offset y0 (EAZ) — in the serial chain, the lever of an axis comes from
/// the axes above it or from the tool offset, so the offsets are placed accordingly. Line 10+:
/// body diagonals in vector (sequential-step) mode: at each step X, then Y, then Z move to
/// their next node and the laser is read after each sub-move (seed §1), beam along the diagonal;
/// for tool offset o the ids are 9 + 4o + (0 (+,+,+) — the seed's line 10 —, 1 (−,+,+),
/// 2 (+,−,+), 3 (+,+,−)); the sign pattern says which axes run backwards. All positions vectors must have the same length for
/// the diagonals.
pub fn seed001_plan(spec: &Seed001Plan) -> Result<Vec<PlannedReading>, LaserLsError> {
    for p in &spec.positions {
        check_positions(p)?;
    }
    if spec.offsets.iter().chain(spec.diagonal_tool_offsets.iter().flatten()).any(|v| !v.is_finite()) {
        return bad("offsets must be finite".into());
    }
    let [x0, y0, z0] = spec.offsets;
    let zero = [0.0; 3];
    // (moving axis, fixed q of the others, tool offset, label)
    let lines: [(usize, [f64; 3], [f64; 3], &str); 9] = [
        (0, [0.0, 0.0, 0.0], zero, "1: X positioning"),
        (1, [0.0, 0.0, 0.0], zero, "2: Y positioning"),
        (2, [0.0, 0.0, 0.0], zero, "3: Z positioning"),
        (0, [0.0, y0, 0.0], zero, "4: X at y0"),
        (1, [0.0, 0.0, z0], zero, "5: Y at z0"),
        (2, [0.0, 0.0, 0.0], [x0, 0.0, 0.0], "6: Z, tool offset x0"),
        (0, [0.0, 0.0, z0], zero, "7: X at z0"),
        (1, [0.0, 0.0, 0.0], [x0, 0.0, 0.0], "8: Y, tool offset x0"),
        (2, [0.0, 0.0, 0.0], [0.0, y0, 0.0], "9: Z, tool offset y0"),
    ];
    let mut plan = Vec::new();
    for (id, (ax, fixed, tool, label)) in lines.iter().enumerate() {
        for &q in &spec.positions[*ax] {
            let mut qq = fixed.to_vec();
            qq[*ax] = q;
            plan.push(PlannedReading { q: qq, point: *tool, direction: unit(*ax), line: id, label: label.to_string() });
        }
    }
    if spec.diagonals {
        let n = spec.positions[0].len();
        if spec.positions.iter().any(|p| p.len() != n) {
            return bad("the diagonals need the same number of positions on X, Y and Z".into());
        }
        let signs: [[f64; 3]; 4] = [[1.0, 1.0, 1.0], [-1.0, 1.0, 1.0], [1.0, -1.0, 1.0], [1.0, 1.0, -1.0]];
        for (oi, tool) in spec.diagonal_tool_offsets.iter().enumerate() {
            for (di, sg) in signs.iter().enumerate() {
                let id = 9 + 4 * oi + di;
                let node = |ax: usize, i: usize| -> f64 {
                    if sg[ax] > 0.0 {
                        spec.positions[ax][i]
                    } else {
                        spec.positions[ax][n - 1 - i]
                    }
                };
                let span: Vec<f64> = (0..3).map(|a| spec.positions[a][n - 1] - spec.positions[a][0]).collect();
                let len = (span[0].powi(2) + span[1].powi(2) + span[2].powi(2)).sqrt();
                let u = [sg[0] * span[0] / len, sg[1] * span[1] / len, sg[2] * span[2] / len];
                let label =
                    format!("{}: diagonal ({:+},{:+},{:+}), tool offset {:?}", id + 1, sg[0], sg[1], sg[2], tool);
                let mut q = vec![node(0, 0), node(1, 0), node(2, 0)];
                plan.push(PlannedReading { q: q.clone(), point: *tool, direction: u, line: id, label: label.clone() });
                for i in 1..n {
                    for ax in 0..3 {
                        q[ax] = node(ax, i);
                        plan.push(PlannedReading {
                            q: q.clone(),
                            point: *tool,
                            direction: u,
                            line: id,
                            label: label.clone(),
                        });
                    }
                }
            }
        }
    }
    Ok(plan)
}

/// Seed 001's own evaluation (Gan, Liu, Zhao 2013, §2), as written, from lines 1–9 of
/// [`seed001_plan`] (values relative to each line's start, one value per node).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Seed001Result {
    /// Error-motion profiles at the nodes, ISO names, ISO signs (angles relative to the first
    /// node, straightness about the least-squares line).
    pub profiles: Vec<(String, Vec<f64>)>,
    /// Squareness (rad) by §2.5: θ = θ2 − θ1 from the least-squares lines of the
    /// integrated-angle straightness curves, mapped to [EC0Y, EB0Z, EA0Z].
    pub squareness: [(String, f64); 3],
}

/// Seed 001's formulas (eqs. 9–15 and §2.5), line values `lines[l][i]` (m) at node i of line l
/// (l = 0..9 as in [`seed001_plan`]):
/// * eq. (9) positioning: EXX(x_i) = ΔL_1(x_i), EYY = ΔL_2, EZZ = ΔL_3;
/// * eqs. (10)–(11) angles from line differences divided by the offset, e.g.
///   ECX(x_i) = [ΔL_1(x_i) − ΔL_4(x_i)]/y0, EBX = [ΔL_7 − ΔL_1]/z0, EAY = [ΔL_2 − ΔL_5]/z0,
///   ECY = [ΔL_8 − ΔL_2]/x0, EBZ = [ΔL_3 − ΔL_6]/x0, EAZ = [ΔL_9 − ΔL_3]/y0 (signs of the
///   serial-chain model; the seed's printed signs are illegible in places);
/// * eqs. (13)–(15) straightness as the integral of the angle minus its least-squares line,
///   δ(x) = ∫₀ˣ ε dx − (c0 + c1 x), with the kinematic signs EYX' = ECX, EZX' = −EBX,
///   EXY' = −ECY, EZY' = EAY, EXZ' = EBZ, EYZ' = −EAZ (path tangent = body heading);
/// * §2.5 squareness θ = θ2 − θ1 with θ1 = arctan of the LS slope of δy(x), θ2 of δx(y) (before
///   removing the lines), likewise for the other pairs.
///
/// Roll (seed §2.6, line 10) is not evaluated here: the printed formulas are illegible and the
/// three-component decomposition of a single diagonal reading is not derivable in the serial chain;
/// the general identifier ([`identify`] on the full plan) gives the rolls.
pub fn seed001_formulas(
    positions: &[Vec<f64>; 3],
    offsets: [f64; 3],
    lines: &[Vec<f64>],
) -> Result<Seed001Result, LaserLsError> {
    for p in positions {
        check_positions(p)?;
    }
    if lines.len() < 9 {
        return bad(format!(
            "expected the 9 lines of the laser-Doppler 21-error layout (docs/methods.md), got {}",
            lines.len()
        ));
    }
    let moving = [0, 1, 2, 0, 1, 2, 0, 1, 2];
    for (l, v) in lines.iter().take(9).enumerate() {
        if v.len() != positions[moving[l]].len() {
            return bad(format!("line {}: expected {} values, got {}", l + 1, positions[moving[l]].len(), v.len()));
        }
        if v.iter().any(|x| !x.is_finite()) {
            return bad(format!("line {}: NaN or infinite value", l + 1));
        }
    }
    let [x0, y0, z0] = offsets;
    if offsets.iter().any(|o| !o.is_finite() || *o == 0.0) {
        return bad(format!("offsets x0, y0, z0 must be finite and non-zero, got {offsets:?}"));
    }
    let rel = |v: &Vec<f64>| -> Vec<f64> { v.iter().map(|x| x - v[0]).collect() };
    let l: Vec<Vec<f64>> = lines.iter().take(9).map(rel).collect();
    let diff = |a: usize, b: usize, s: f64| -> Vec<f64> { l[a].iter().zip(&l[b]).map(|(p, q)| (p - q) / s).collect() };
    let ecx = diff(0, 3, y0);
    let ebx = diff(6, 0, z0);
    let eay = diff(1, 4, z0);
    let ecy = diff(7, 1, x0);
    let ebz = diff(2, 5, x0);
    let eaz = diff(8, 2, y0);
    let integrate = |pos: &[f64], f: &[f64], sgn: f64| -> Vec<f64> {
        let mut out = vec![0.0; f.len()];
        for i in 1..f.len() {
            out[i] = out[i - 1] + sgn * 0.5 * (f[i] + f[i - 1]) * (pos[i] - pos[i - 1]);
        }
        out
    };
    let (px, py, pz) = (&positions[0], &positions[1], &positions[2]);
    let i_yx = integrate(px, &ecx, 1.0);
    let i_zx = integrate(px, &ebx, -1.0);
    let i_xy = integrate(py, &ecy, -1.0);
    let i_zy = integrate(py, &eay, 1.0);
    let i_xz = integrate(pz, &ebz, 1.0);
    let i_yz = integrate(pz, &eaz, -1.0);
    use crate::line::{fit_line, remove_line};
    let slope = |p: &[f64], v: &[f64]| fit_line(p, v).1.atan();
    // §2.5: θ = θ2 − θ1, mapped to ISO (EC0Y = −(angle deviation from 90°) etc., see module doc)
    let sq_xy = -(slope(px, &i_yx) + slope(py, &i_xy));
    let sq_xz = slope(px, &i_zx) + slope(pz, &i_xz);
    let sq_yz = -(slope(py, &i_zy) + slope(pz, &i_yz));
    let profiles = vec![
        ("EXX".to_string(), l[0].clone()),
        ("EYX".to_string(), remove_line(px, &i_yx)),
        ("EZX".to_string(), remove_line(px, &i_zx)),
        ("EBX".to_string(), ebx),
        ("ECX".to_string(), ecx),
        ("EXY".to_string(), remove_line(py, &i_xy)),
        ("EYY".to_string(), l[1].clone()),
        ("EZY".to_string(), remove_line(py, &i_zy)),
        ("EAY".to_string(), eay),
        ("ECY".to_string(), ecy),
        ("EXZ".to_string(), remove_line(pz, &i_xz)),
        ("EYZ".to_string(), remove_line(pz, &i_yz)),
        ("EZZ".to_string(), l[2].clone()),
        ("EAZ".to_string(), eaz),
        ("EBZ".to_string(), ebz),
    ];
    Ok(Seed001Result {
        profiles,
        squareness: [("EC0Y".to_string(), sq_xy), ("EB0Z".to_string(), sq_xz), ("EA0Z".to_string(), sq_yz)],
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn legendre_and_nodes_bases_evaluate_as_documented() {
        let mut b = Vec::new();
        Basis::Legendre { order: 3, lo: 0.0, hi: 2.0 }.eval(1.5, &mut b).unwrap();
        // t = 0.5: P0 = 1, P1 = 0.5, P2 = (3·0.25 − 1)/2 = −0.125, P3 = (5·0.125 − 1.5)/2 = −0.4375
        let want = [1.0, 0.5, -0.125, -0.4375];
        for (g, w) in b.iter().zip(want) {
            assert!((g - w).abs() < 1e-15, "{g} vs {w}");
        }
        Basis::Nodes(vec![0.0, 0.1, 0.3]).eval(0.2, &mut b).unwrap();
        // 0.2 is halfway between 0.1 and 0.3 (rounding of the decimal inputs: 1e-15)
        assert!(b[0] == 0.0 && (b[1] - 0.5).abs() < 1e-15 && (b[2] - 0.5).abs() < 1e-15);
        assert!(Basis::Nodes(vec![0.0, 0.1]).eval(0.2, &mut b).is_err());
    }

    #[test]
    fn closed_form_inverts_the_hand_written_model() {
        // Hand-worked forward model of the doc comment with e = [1, 2, 3, 4, 5, 6]·1e-6.
        let pts = [[0.1, 0.25, 0.3], [0.0, -0.25, 0.8], [0.05, 0.0, 1.2]];
        let e = [1e-6, 2e-6, 3e-6, 4e-6, 5e-6, 6e-6];
        let m = [
            e[0] + pts[0][2] * e[4] - pts[0][1] * e[5],
            e[0] + pts[1][2] * e[4] - pts[1][1] * e[5],
            e[0] + pts[2][2] * e[4] - pts[2][1] * e[5],
            e[1] + pts[0][0] * e[5] - pts[0][2] * e[3],
            e[1] + pts[1][0] * e[5] - pts[1][2] * e[3],
            e[2] + pts[0][1] * e[3] - pts[0][0] * e[4],
        ];
        let got = nine_line_closed_form(&pts, m).unwrap();
        for (g, w) in got.iter().zip(e) {
            // exact arithmetic up to rounding of ~1e-6 values: 1e-18
            assert!((g - w).abs() < 1e-18, "{g} vs {w}");
        }
        let collinear = [[0.0, 0.0, 0.3], [0.0, 0.0, 0.8], [0.0, 0.0, 1.2]];
        assert!(nine_line_closed_form(&collinear, m).is_err());
    }

    #[test]
    fn kmeans_separates_three_obvious_clusters_deterministically() {
        let mut f = Vec::new();
        for c in 0..3 {
            for i in 0..5 {
                f.push(vec![c as f64 * 10.0 + i as f64 * 0.1, -(c as f64) * 5.0]);
            }
        }
        let a = kmeans(&f, 3, 7, 50).unwrap();
        let b = kmeans(&f, 3, 7, 50).unwrap();
        assert_eq!(a, b);
        for c in 0..3 {
            let l = a.labels[c * 5];
            assert!((0..5).all(|i| a.labels[c * 5 + i] == l));
        }
        assert!(kmeans(&f, 0, 1, 10).is_err());
        assert!(kmeans(&[vec![f64::NAN]], 1, 1, 10).is_err());
    }

    #[test]
    fn rejects_bad_readings() {
        let model = Model { axes: vec![AxisModel::with_nodes(Axis::X, &[0.0, 0.5, 1.0])], squareness: false };
        let r = Reading {
            q: vec![0.5],
            point: [0.0; 3],
            direction: [1.0, 0.0, 0.0],
            value: f64::NAN,
            sigma: 1e-8,
            line: Some(0),
        };
        let e = identify(std::slice::from_ref(&r), &model, &IdOptions::default()).unwrap_err();
        assert!(e.to_string().contains("NaN"), "{e}");
        let mut r2 = r.clone();
        r2.value = 0.0;
        r2.direction = [1.0, 1.0, 0.0];
        assert!(identify(&[r2], &model, &IdOptions::default()).is_err());
        let mut r3 = r;
        r3.value = 0.0;
        r3.q = vec![1.5];
        let e = identify(&[r3], &model, &IdOptions::default()).unwrap_err();
        assert!(e.to_string().contains("outside"), "{e}");
    }
}
