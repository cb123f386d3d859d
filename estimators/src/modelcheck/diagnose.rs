//! Candidate ranking of `vmt diagnose` (DESIGN.md §8; FORMAT.md §4 `ranking`).
//!
//! A [`Candidate`] is a named effect whose *signature* maps hyper-parameters (a period, a time
//! constant, a Stribeck velocity...) to design columns, one value per residual sample. For each
//! candidate the hyper-parameters are searched on a grid and refined jointly by Levenberg–Marquardt
//! over variable projection ([`super::refine`]; golden-section search where the solver cannot
//! improve), the linear coefficients are fitted by weighted least squares together with the model's base
//! columns, and the fit is scored by the change of the Bayesian information criterion
//! (Schwarz 1978; Kass & Raftery 1995, J. Am. Stat. Assoc. 90:773):
//!
//! - σ known:   ΔBIC = χ²_new − χ²_old + k·ln n,
//! - σ unknown: ΔBIC = n·ln(RSS_new/RSS_old) + k·ln n  (the profile likelihood of a Gaussian with
//!   unknown variance: −2 ln L = n·ln(RSS/n) + const),
//!
//! where n is the number of samples and k counts the candidate's linear coefficients **plus its
//! searched hyper-parameters**. Counting a searched hyper-parameter as a parameter is the
//! look-elsewhere correction: a period searched over M independent frequencies can raise the
//! best χ² reduction of pure noise by about 2·ln M ≤ 2·ln n, and the k·ln n penalty of the
//! three parameters of a sinusoid (two amplitudes + the period) with the −10 threshold keeps the
//! false-alarm probability of one searched sinusoid near M·e^{−(3 ln n + 10)/2} (≈ 10⁻⁵ for
//! n = 400, M = 400); see the false-alarm test in `tests/modelcheck.rs` for the measured rate.
//!
//! Beside ΔBIC each candidate gets a false-alarm probability for the whole diagnosis
//! ([`CandidateFit::p_value`]): with q independent new columns, the reduction Δχ² of pure noise at
//! one hyper-parameter value is χ²(q) (σ known; with σ's scale free, Δχ²·(n − p)/χ²_new, the
//! large-n form of the F test); a search over M grid values and a ranking of C candidates raise the
//! chance that some value of some candidate reaches it, bounded by Bonferroni:
//! p = min(1, C·M·P(χ²_q > Δχ²)). A candidate is significant only when p ≤ `family_alpha` (1 %):
//! the false-alarm probability of one whole `diagnose` on a complete model is then ≤ 1 % by this
//! bound (M counts the searched grid values; the golden-section refinement between two of them is
//! not counted, which the measured rates in `tests/gen_diagnose.rs` check).
//!
//! Verdicts (see [`rank_candidates`]): `significant` when ΔBIC < −10 ("very strong" evidence in
//! Kass & Raftery's scale) and p ≤ `family_alpha`, the candidate explains at least a small fraction of the residual,
//! and it is not explained away by better-ranked significant candidates; `inseparable` when two
//! significant candidates fit nearly the same vector on THIS data (cosine > 0.98) with ΔBIC
//! closer than 10; `noise` otherwise.

use super::lsq::{fit_signature, Basis};
use super::ortho::{OrthoBase, SparseColumn};
use super::{check_finite, check_len, ModelCheckError, Sigma};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;

/// The signature of a candidate: hyper-parameter values (in the order of
/// [`Candidate::hyper_parameters`]) → design columns, one `Vec` of n values per linear
/// coefficient. An `Err` marks a hyper-parameter value as invalid (it is skipped in the search).
pub type SignatureFn<'a> = dyn Fn(&[f64]) -> Result<Vec<Vec<f64>>, ModelCheckError> + Send + Sync + 'a;

/// A signature's columns as runs ([`Candidate::with_sparse`]): the same values as the
/// [`SignatureFn`]'s, zero outside the runs.
pub type SparseSignatureFn<'a> = dyn Fn(&[f64]) -> Result<Vec<SparseColumn>, ModelCheckError> + Send + Sync + 'a;

/// Optional conversion of (coefficients, hyper-parameters) into the reported `params` (e.g. a
/// sine and cosine coefficient into amplitude and phase).
pub type DescribeFn<'a> = dyn Fn(&[f64], &[f64]) -> BTreeMap<String, f64> + Send + Sync + 'a;

/// A hyper-parameter searched on a grid (then refined between the neighbours of the best grid
/// value, jointly with the candidate's other refinable ones, when `refine` is set), in its own unit
/// (s, m, m/s...).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct HyperParameter {
    /// Name used in `params` (e.g. "period", "tau").
    pub name: String,
    /// Grid of values to try; a grid of one value is a fixed, not-searched parameter.
    pub grid: Vec<f64>,
    /// Refine the best grid value (module doc).
    pub refine: bool,
}

/// A candidate effect for `diagnose`.
pub struct Candidate<'a> {
    /// Effect name as in FORMAT.md (e.g. "backlash", "thermal_expansion").
    pub effect: String,
    /// Names of the linear coefficients, one per signature column (used in `params`).
    pub coefficient_names: Vec<String>,
    /// Searched hyper-parameters.
    pub hyper_parameters: Vec<HyperParameter>,
    /// Hyper-parameters → columns.
    pub signature: Box<SignatureFn<'a>>,
    /// Optional conversion of the fitted numbers into `params`.
    pub describe: Option<Box<DescribeFn<'a>>>,
    /// The signature's columns as runs ([`Candidate::with_sparse`]), for the grid search.
    pub sparse: Option<Box<SparseSignatureFn<'a>>>,
    /// Screened search ([`Candidate::with_screen`]): the number of grid points evaluated exactly.
    pub screen: Option<usize>,
    /// A grid chosen from the data ([`Candidate::chosen_from`]): the number of independent
    /// hyper-parameter values it was chosen from, counted instead of the grid's size in the
    /// look-elsewhere correction of [`CandidateFit::p_value`].
    pub chosen_from: Option<usize>,
}

impl<'a> Candidate<'a> {
    /// A candidate with linear coefficients named `coefficient_names` and a signature function.
    pub fn new(
        effect: &str,
        coefficient_names: &[&str],
        signature: impl Fn(&[f64]) -> Result<Vec<Vec<f64>>, ModelCheckError> + Send + Sync + 'a,
    ) -> Self {
        Candidate {
            effect: effect.to_string(),
            coefficient_names: coefficient_names.iter().map(|s| s.to_string()).collect(),
            hyper_parameters: Vec::new(),
            signature: Box::new(signature),
            describe: None,
            sparse: None,
            screen: None,
            chosen_from: None,
        }
    }

    /// Adds a hyper-parameter searched over `grid` and refined (module doc).
    pub fn with_hyper(mut self, name: &str, grid: Vec<f64>) -> Self {
        self.hyper_parameters.push(HyperParameter { name: name.to_string(), grid, refine: true });
        self
    }

    /// Sets the conversion of (coefficients, hyper-parameters) into the reported `params`.
    pub fn with_describe(mut self, f: impl Fn(&[f64], &[f64]) -> BTreeMap<String, f64> + Send + Sync + 'a) -> Self {
        self.describe = Some(Box::new(f));
        self
    }

    /// Gives the signature's columns also as runs ([`SparseColumn`]: the same values, zero outside
    /// the runs), which the exact grid search then evaluates without the zeros. For a candidate
    /// whose columns each live on a few channels of a long stack (a structural mode).
    pub fn with_sparse(
        mut self,
        f: impl Fn(&[f64]) -> Result<Vec<SparseColumn>, ModelCheckError> + Send + Sync + 'a,
    ) -> Self {
        self.sparse = Some(Box::new(f));
        self
    }

    /// Screens the grid: every grid point is scored by the reduction of the base-projected
    /// residual on the candidate's weighted columns *without* their projection on the base (cheap
    /// when the base is large), and only the `top` best of those are evaluated exactly; the
    /// refinement and the reported fit are exact. For candidates with many columns over a large
    /// base (a structural mode over flexible shapes). The score is a lower bound of the exact
    /// reduction, not an upper one: with r off the base, projecting the columns C off the base
    /// leaves Cᵀr as it is and only shrinks CᵀC, so a point whose columns the base partly spans
    /// scores below its exact reduction.
    pub fn with_screen(mut self, top: usize) -> Self {
        self.screen = Some(top.max(1));
        self
    }

    /// The grid was chosen from the data out of `independent` independent values (a period found
    /// by a periodogram over a wide range, then evaluated exactly at its best peaks): the p-value
    /// counts `independent` searched values, not the grid's few (the look-elsewhere effect of the
    /// search that chose them).
    pub fn chosen_from(mut self, independent: usize) -> Self {
        self.chosen_from = Some(independent.max(1));
        self
    }

    /// Number of searched hyper-parameters (grids with more than one value; every one of a grid
    /// chosen from the data).
    fn searched(&self) -> usize {
        self.hyper_parameters.iter().filter(|h| h.grid.len() > 1 || self.chosen_from.is_some()).count()
    }
}

/// Thresholds of the verdicts.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct DiagnoseConfig {
    /// ΔBIC below which a candidate can be significant (default −10: "very strong" evidence,
    /// Kass & Raftery 1995).
    pub significance_threshold: f64,
    /// Minimum explained fraction 1 − RSS_new/RSS_old for significance (default 0.01): with very
    /// many samples a negligible effect can pass the ΔBIC threshold; it is then not worth adding.
    pub explained_floor: f64,
    /// |cos| between the fitted signature vectors (weighted, base removed) above which two
    /// candidates are collinear on this data (default 0.98).
    pub collinearity_cosine: f64,
    /// ΔBIC difference below which two collinear candidates are inseparable (default 10).
    pub inseparable_margin: f64,
    /// Evaluation budget of a candidate's refinement (default 40): Levenberg–Marquardt residual
    /// evaluations of the joint refinement, or golden-section iterations per hyper-parameter where
    /// the solver cannot improve on the grid.
    pub refine_iterations: usize,
    /// Largest number of points of a candidate's hyper-parameter grid (default 200 000).
    pub max_grid_points: usize,
    /// Maximum number of effects [`forward_select`] adds (default 5).
    pub max_steps: usize,
    /// Largest false-alarm probability of the whole diagnosis ([`CandidateFit::p_value`]) for a
    /// significant verdict (default 0.01).
    pub family_alpha: f64,
}

impl Default for DiagnoseConfig {
    fn default() -> Self {
        DiagnoseConfig {
            significance_threshold: -10.0,
            explained_floor: 0.01,
            collinearity_cosine: 0.98,
            inseparable_margin: 10.0,
            refine_iterations: 40,
            max_grid_points: 200_000,
            max_steps: 5,
            family_alpha: 0.01,
        }
    }
}

/// Verdict of a candidate, serialised as "significant", "noise" or "inseparable".
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Verdict {
    /// Explains a real part of the residual.
    Significant,
    /// Indistinguishable from noise (or explained away by a better candidate).
    Noise,
    /// Explains the residual but cannot be told apart from `confused_with` on this data.
    Inseparable,
}

/// One entry of FORMAT.md §4 `ranking` (serialises exactly to its keys).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RankingEntry {
    /// Effect name.
    pub effect: String,
    /// ΔBIC of adding the effect alone (negative favours the effect).
    pub delta_bic: f64,
    /// Explained fraction 1 − RSS_new/RSS_old (weighted by 1/σ² when σ is known).
    pub explained: f64,
    /// The verdict.
    pub verdict: Verdict,
    /// Fitted coefficients and hyper-parameters by name, SI units.
    pub params: BTreeMap<String, f64>,
    /// Effects this one is inseparable from.
    pub confused_with: Vec<String>,
    /// Why the candidate was not tried or cannot be seen in this data (FORMAT.md §4 optional `note`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub note: Option<String>,
    /// Other periods (m) that fit exactly as well on these sample positions (optional `aliases`).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub aliases: Vec<f64>,
    /// Upper bound of the probability that noise alone gives some candidate of this diagnosis a
    /// reduction this large, searches counted ([`CandidateFit::p_value`]; optional `p_value`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub p_value: Option<f64>,
    /// Number of hyper-parameter values searched for this candidate (optional `searched`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub searched: Option<usize>,
    /// Searched hyper-parameters whose best value lies at an end of the range searched
    /// ([`CandidateFit::hyper_at_bound`]; optional `at_bound`): a bound, not an estimate.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub at_bound: Vec<String>,
    /// The orders of the model's fitted shapes with this candidate in the model, re-chosen by BIC
    /// (optional `shape_orders`, `vmt diagnose`): what the candidate's ΔBIC was computed against.
    #[serde(default, skip_serializing_if = "BTreeMap::is_empty")]
    pub shape_orders: BTreeMap<String, u32>,
}

/// The full fit of one candidate (details behind a [`RankingEntry`]).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CandidateFit {
    /// Effect name.
    pub effect: String,
    /// Linear coefficients by name, residual unit per column unit.
    pub coefficients: BTreeMap<String, f64>,
    /// Their standard errors (hyper-parameters held at their fitted values).
    pub std_errors: BTreeMap<String, f64>,
    /// Standard errors of the jointly refined hyper-parameters by name, coefficients profiled out
    /// ([`super::refine`]); absent where the refinement fell back to the grid or golden section, or
    /// the curvature is not positive.
    #[serde(default, skip_serializing_if = "BTreeMap::is_empty")]
    pub hyper_std_errors: BTreeMap<String, f64>,
    /// Fitted hyper-parameters by name.
    pub hyper_parameters: BTreeMap<String, f64>,
    /// Searched, refined hyper-parameters (a continuous range, not a list of catalogue values)
    /// whose best value (after the refinement) lies at an end of their grid, within 1 % of the step to its neighbour: the criterion still improves towards the
    /// bound, so the best value lies at or beyond the range searched and the number is a bound of
    /// the search, not an estimate (no standard error is reported for it).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub hyper_at_bound: Vec<String>,
    /// Reported params (coefficients + hyper-parameters, or the candidate's `describe`).
    pub params: BTreeMap<String, f64>,
    /// Number of samples n.
    pub n: usize,
    /// Number of new parameters k (coefficients + searched hyper-parameters).
    pub k: usize,
    /// χ² before / after (σ known), base columns fitted in both.
    pub chi2_old: Option<f64>,
    /// χ² after adding the candidate (σ known).
    pub chi2_new: Option<f64>,
    /// Unweighted RSS before (base columns fitted), residual unit squared.
    pub rss_old: f64,
    /// Unweighted RSS after adding the candidate.
    pub rss_new: f64,
    /// ΔBIC (module doc).
    pub delta_bic: f64,
    /// Explained fraction 1 − stat_new/stat_old with stat = χ² (σ known) or RSS.
    pub explained: f64,
    /// ΔBIC of the candidate added after the better-ranked significant candidates (filled by
    /// [`rank_candidates`] for marginally significant candidates), with its hyper-parameters held.
    pub conditional_delta_bic: Option<f64>,
    /// Number of signature evaluations of the search.
    pub evaluations: usize,
    /// Number M of hyper-parameter grid values searched (the product of the searched grids' sizes; 1
    /// without a search).
    pub searched: usize,
    /// P(χ²_q > Δχ²)·M for this candidate alone (module doc); [`rank_candidates`] multiplies it by
    /// the number of candidates C and caps it at 1.
    pub p_value: f64,
    /// The candidate's columns at the fitted hyper-parameters.
    #[serde(skip)]
    pub columns: Vec<Vec<f64>>,
    /// Residual after fitting base + candidate columns.
    #[serde(skip)]
    pub new_residual: Vec<f64>,
    /// Weighted fitted change (W^{1/2}(r_old − r_new)), used for the collinearity test.
    #[serde(skip)]
    fitted_change: Vec<f64>,
}

/// The residual to diagnose.
#[derive(Debug, Clone, Copy)]
pub struct ResidualInput<'a> {
    /// Residual y − ŷ per sample, e.g. in m.
    pub residual: &'a [f64],
    /// Its noise standard deviation.
    pub sigma: &'a Sigma,
    /// Columns always refitted with every candidate (e.g. a constant offset, the model's own
    /// free parameters' sensitivities); may be empty.
    pub base_columns: &'a [Vec<f64>],
}

/// Result of [`rank_candidates`]: the ranking and, in the same order, the fits behind it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Diagnosis {
    /// FORMAT.md §4 `ranking`, best first, every candidate tried.
    pub ranking: Vec<RankingEntry>,
    /// Details, same order as `ranking`.
    pub fits: Vec<CandidateFit>,
    /// χ² (σ known) or RSS of the residual after the base columns.
    pub stat_old: f64,
    /// Number of samples.
    pub n: usize,
}

/// The most grid points whose columns are projected together ([`OrthoBase::explained_each`]).
const GRID_CHUNK_POINTS: usize = 32;

/// The most column values (points × columns × samples) a chunk of grid points holds (64 MB).
const GRID_CHUNK_VALUES: usize = 8_000_000;

/// Prepared residual: weights, orthonormal weighted base (one QR, reused for every candidate and
/// hyper-parameter value: variable projection), weighted residual with base removed.
struct Prepared {
    n: usize,
    w: Vec<f64>,
    base: OrthoBase,
    r_t: Vec<f64>,
    stat_old: f64,
    rss_old: f64,
    known: bool,
}

fn prepare(input: &ResidualInput) -> Result<Prepared, ModelCheckError> {
    let n = input.residual.len();
    if n < 3 {
        return Err(ModelCheckError::TooFewSamples { what: "diagnose".into(), need: 3, got: n });
    }
    check_finite("residual", input.residual)?;
    let w = input.sigma.weights(n)?;
    for (j, c) in input.base_columns.iter().enumerate() {
        check_len(&format!("base column {j}"), n, c.len())?;
        check_finite(&format!("base column {j}"), c)?;
    }
    let base = OrthoBase::new(input.base_columns, &w)?;
    prepared_on(input, w, base)
}

/// [`prepare`]'s statistics of `input`'s residual on the basis `base` of its base columns (and
/// any columns added to them), weights `w`.
fn prepared_on(input: &ResidualInput, w: Vec<f64>, base: OrthoBase) -> Result<Prepared, ModelCheckError> {
    let n = input.residual.len();
    let total: f64 = input.residual.iter().zip(&w).map(|(r, w)| (r * w).powi(2)).sum();
    let r_t = base.project_vector(input.residual, &w);
    let stat_old: f64 = r_t.iter().map(|x| x * x).sum();
    // Rounding level: the base leaves less than 1e-12 of the residual's norm.
    if stat_old <= 1e-24 * total || stat_old == 0.0 {
        return Err(ModelCheckError::NothingToExplain);
    }
    // The unweighted residual of the weighted fit is W⁻¹·(what the projection leaves of W·r).
    let rss_old = r_t.iter().zip(&w).map(|(r, w)| (r / w).powi(2)).sum();
    Ok(Prepared { n, w, base, r_t, stat_old, rss_old, known: input.sigma.is_known() })
}

fn delta_bic(p: &Prepared, stat_new: f64, k: usize) -> f64 {
    let pen = k as f64 * (p.n as f64).ln();
    if p.known {
        stat_new - p.stat_old + pen
    } else {
        // Floor: a perfect fit would give ln 0.
        let ratio = (stat_new / p.stat_old).max(1e-300);
        p.n as f64 * ratio.ln() + pen
    }
}

/// Orthonormal basis of the candidate's weighted columns with the base projected out; a column
/// whose remaining norm is below 1e-9 of its own (dependent on the base or the others) is dropped,
/// so its size is the number q of new independent columns.
fn candidate_basis(p: &Prepared, cols: &[Vec<f64>]) -> Basis {
    let mut b = Basis::default();
    for v in p.base.project_columns(cols, &p.w).into_iter().filter(|v| v.iter().any(|x| *x != 0.0)) {
        b.push(v);
    }
    b
}

/// The candidate's signature at `h`, checked: one column per coefficient name, n finite values each.
fn checked_columns(p: &Prepared, cand: &Candidate, h: &[f64]) -> Result<Vec<Vec<f64>>, ModelCheckError> {
    let cols = (cand.signature)(h)?;
    check_len("signature columns (one per coefficient name)", cand.coefficient_names.len(), cols.len())?;
    for (j, c) in cols.iter().enumerate() {
        let what = || format!("signature column {j}");
        check_len(&what(), p.n, c.len())?;
        if let Some(i) = c.iter().position(|x| !x.is_finite()) {
            return Err(ModelCheckError::NotFinite { what: what(), index: i, value: c[i] });
        }
    }
    Ok(cols)
}

/// The candidate's signature at `h` as runs (its [`Candidate::with_sparse`] `sparse`), checked: one
/// column per coefficient name, each run inside the n rows, after the one before it, its values
/// finite.
fn checked_sparse(
    p: &Prepared,
    cand: &Candidate,
    sparse: &SparseSignatureFn,
    h: &[f64],
) -> Result<Vec<SparseColumn>, ModelCheckError> {
    let cols = sparse(h)?;
    check_len("signature columns (one per coefficient name)", cand.coefficient_names.len(), cols.len())?;
    for (j, c) in cols.iter().enumerate() {
        let mut next = 0;
        for (lo, v) in &c.runs {
            let hi = lo.checked_add(v.len()).filter(|hi| *lo >= next && *hi <= p.n);
            let Some(hi) = hi else {
                return Err(ModelCheckError::Invalid(format!(
                    "signature column {j}: a run at rows {lo}..{} is not after the one before it (row {next}) \
                     inside the {} rows",
                    lo.saturating_add(v.len()),
                    p.n
                )));
            };
            if let Some(i) = v.iter().position(|x| !x.is_finite()) {
                return Err(ModelCheckError::NotFinite {
                    what: format!("signature column {j}"),
                    index: lo + i,
                    value: v[i],
                });
            }
            next = hi;
        }
    }
    Ok(cols)
}

/// Evaluates a candidate's signature at `h` and returns (χ² or RSS reduction, columns).
fn reduction(p: &Prepared, cand: &Candidate, h: &[f64]) -> Result<(f64, Vec<Vec<f64>>), ModelCheckError> {
    let cols = checked_columns(p, cand, h)?;
    Ok((reduction_of(p, &cols), cols))
}

/// The weighted residual that base + candidate columns at `h` leave, P⊥(h)·W^{1/2}·r (the
/// variable-projection residual [`super::refine`] minimises; its squared norm is χ²_new or the
/// weighted RSS).
fn projected_residual(p: &Prepared, cand: &Candidate, h: &[f64]) -> Result<Vec<f64>, ModelCheckError> {
    let cols = checked_columns(p, cand, h)?;
    Ok(p.base.projected_fit(&p.r_t, &cols, &p.w, true).1.unwrap_or_else(|| p.r_t.clone()))
}

/// The screening score of a candidate at `h` ([`Candidate::with_screen`]): ‖projection of the
/// base-projected weighted residual on the candidate's weighted columns‖², the columns not
/// projected on the base.
fn screen_score(p: &Prepared, cand: &Candidate, h: &[f64]) -> Result<f64, ModelCheckError> {
    let cols = checked_columns(p, cand, h)?;
    Ok(span_projection(&cols, &p.w, &p.r_t))
}

/// ‖P_C·r‖² for the weighted columns C = W·`cols` (r already weighted): [`OrthoBase::projected_fit`]
/// over an empty span (G = CᵀC, b = Cᵀr over each column's non-zero rows, dependent columns dropped).
fn span_projection(cols: &[Vec<f64>], w: &[f64], r: &[f64]) -> f64 {
    match OrthoBase::new(&[], w) {
        Ok(empty) => empty.projected_fit(r, cols, w, false).0,
        Err(_) => f64::NEG_INFINITY,
    }
}

/// The χ² (or RSS) reduction of adding `cols` to the prepared base (variable projection: the base
/// is factored once in [`prepare`]).
///
/// In Gram form ([`OrthoBase::projected_fit`]): the search's evaluations. The candidate's reported
/// fit at its best values is the exact one (projected columns, orthogonalised, SVD).
fn reduction_of(p: &Prepared, cols: &[Vec<f64>]) -> f64 {
    p.base.projected_fit(&p.r_t, cols, &p.w, false).0
}

/// A chunk of grid points `gs` scored together: each point's columns by `make`, the sets made
/// scored by `score` in one call (one score per set, in order), a point whose columns could not be
/// made keeping its error.
fn score_chunk<C>(
    gs: &[usize],
    make: impl Fn(usize) -> Result<Vec<C>, ModelCheckError>,
    score: impl Fn(&[&[C]]) -> Vec<f64>,
) -> Vec<(usize, Result<f64, ModelCheckError>)> {
    let cols: Vec<Result<Vec<C>, ModelCheckError>> = gs.iter().map(|&g| make(g)).collect();
    let sets: Vec<&[C]> = cols.iter().filter_map(|c| c.as_deref().ok()).collect();
    let mut scores = score(&sets).into_iter();
    gs.iter().zip(cols).map(|(&g, c)| (g, c.map(|_| scores.next().unwrap_or(f64::NEG_INFINITY)))).collect()
}

/// Fits one candidate: grid search of its hyper-parameters, joint refinement, weighted
/// least squares of base + candidate columns ([`fit_signature`]), ΔBIC and explained fraction
/// (module doc for the equations).
pub fn fit_candidate(
    input: &ResidualInput,
    candidate: &Candidate,
    config: &DiagnoseConfig,
) -> Result<CandidateFit, ModelCheckError> {
    let p = prepare(input)?;
    fit_prepared(&p, candidate, config)
}

fn fit_prepared(p: &Prepared, cand: &Candidate, config: &DiagnoseConfig) -> Result<CandidateFit, ModelCheckError> {
    let err = |message: String| ModelCheckError::Candidate { effect: cand.effect.clone(), message };
    if cand.coefficient_names.is_empty() {
        return Err(err("needs at least one coefficient name".into()));
    }
    for h in &cand.hyper_parameters {
        if h.grid.is_empty() {
            return Err(err(format!("hyper-parameter `{}` has an empty grid", h.name)));
        }
        if let Some(v) = h.grid.iter().find(|v| !v.is_finite()) {
            return Err(err(format!("hyper-parameter `{}` grid holds {v}", h.name)));
        }
    }
    let dims: Vec<usize> = cand.hyper_parameters.iter().map(|h| h.grid.len()).collect();
    let total = dims.iter().try_fold(1usize, |a, d| a.checked_mul(*d));
    let total = match total {
        Some(t) if t <= config.max_grid_points => t,
        _ => return Err(err(format!("hyper-parameter grid has more than {} points", config.max_grid_points))),
    };
    // Grid search over the Cartesian product, in parallel over grid points (rayon); the best is
    // then taken in grid order, so the result does not depend on the number of threads.
    let point = |g: usize| -> Vec<f64> {
        let mut rest = g;
        cand.hyper_parameters
            .iter()
            .zip(&dims)
            .map(|(hp, d)| {
                let i = rest % d;
                rest /= d;
                hp.grid[i]
            })
            .collect()
    };
    // The grid points evaluated exactly: all of them, or the best `top` by the screening score.
    let exact_points: Vec<usize> = match cand.screen {
        None => (0..total).collect(),
        Some(top) => {
            let scores: Vec<f64> = (0..total)
                .into_par_iter()
                .map(|g| screen_score(p, cand, &point(g)).unwrap_or(f64::NEG_INFINITY))
                .collect();
            let mut order: Vec<usize> = (0..total).collect();
            order.sort_by(|a, b| scores[*b].total_cmp(&scores[*a]).then(a.cmp(b)));
            order.truncate(top);
            order.sort_unstable();
            order
        }
    };
    // In chunks of grid points whose columns are projected together ([`OrthoBase::explained_each`]:
    // Q is read once per chunk, not once per point), the chunks fixed by the grid and the
    // candidate's columns alone (the same bits on any number of threads) and sized to hold about
    // GRID_CHUNK_VALUES column values.
    // Values per point: dense, a column per coefficient over all rows; as runs, the values of the
    // first exact point's runs (a mode's responses lie on the channels its sensors read, whatever
    // its frequency and damping; a chunk holds at most GRID_CHUNK_POINTS dense points whatever the
    // runs of the others).
    let dense = cand.coefficient_names.len().max(1).saturating_mul(p.n.max(1));
    let per_point = match (&cand.sparse, exact_points.first()) {
        (Some(sparse), Some(&g)) => checked_sparse(p, cand, sparse.as_ref(), &point(g))
            .map_or(dense, |cols| cols.iter().flat_map(|c| &c.runs).map(|(_, v)| v.len()).sum::<usize>().max(1)),
        _ => dense,
    };
    // clamp: GRID_CHUNK_POINTS is 32, above 1.
    let chunk = (GRID_CHUNK_VALUES / per_point).clamp(1, GRID_CHUNK_POINTS);
    let reds: Vec<(usize, Result<f64, ModelCheckError>)> = exact_points
        .par_chunks(chunk)
        .flat_map_iter(|gs| {
            // The runs where the candidate gives them, else the dense columns.
            if let Some(sparse) = &cand.sparse {
                let make = |g: usize| checked_sparse(p, cand, sparse.as_ref(), &point(g));
                score_chunk(gs, make, |sets| p.base.explained_each_sparse(&p.r_t, sets, &p.w))
            } else {
                let make = |g: usize| checked_columns(p, cand, &point(g));
                score_chunk(gs, make, |sets| p.base.explained_each(&p.r_t, sets, &p.w))
            }
        })
        .collect();
    let mut best: Option<(f64, Vec<f64>)> = None;
    let mut first_error: Option<ModelCheckError> = None;
    let mut evaluations = reds.len();
    for (g, r) in reds.into_iter() {
        match r {
            Ok(red) => {
                if best.as_ref().is_none_or(|(b, _)| red > *b) {
                    best = Some((red, point(g)));
                }
            }
            Err(e) => {
                first_error.get_or_insert(e);
            }
        }
    }
    let (mut best_red, mut best_h) = match best {
        Some(b) => b,
        None => return Err(err(first_error.map_or_else(|| "no grid point".into(), |e| e.to_string()))),
    };
    // Joint refinement (Levenberg–Marquardt over variable projection, [`super::refine`]) of the
    // refinable hyper-parameters inside the box between the neighbours of their best grid values;
    // golden-section sweeps, one parameter at a time, where the solver cannot start or does not
    // improve (an invalid value inside the box).
    let free: Vec<usize> = (0..cand.hyper_parameters.len())
        .filter(|d| cand.hyper_parameters[*d].refine && cand.hyper_parameters[*d].grid.len() > 1)
        .collect();
    let bracket = |d: usize, x: f64| -> (f64, f64) {
        let mut g = cand.hyper_parameters[d].grid.clone();
        g.sort_by(|a, b| a.total_cmp(b));
        let i = g.partition_point(|v| *v < x).min(g.len() - 1);
        (g[i.saturating_sub(1)], g[(i + 1).min(g.len() - 1)])
    };
    let mut hyper_se: BTreeMap<String, f64> = BTreeMap::new();
    let mut refined = false;
    if !free.is_empty() {
        let (lo, hi): (Vec<f64>, Vec<f64>) = free.iter().map(|d| bracket(*d, best_h[*d])).unzip();
        let start: Vec<f64> = free.iter().map(|d| best_h[*d]).collect();
        let full = |x: &[f64]| -> Vec<f64> {
            let mut h = best_h.clone();
            free.iter().zip(x).for_each(|(d, v)| h[*d] = *v);
            h
        };
        let f = |x: &[f64]| projected_residual(p, cand, &full(x));
        if let Some(r) = super::refine::refine_projected(&f, &start, &lo, &hi, config.refine_iterations) {
            evaluations += r.evaluations;
            if p.stat_old - r.cost > best_red {
                best_red = p.stat_old - r.cost;
                best_h = full(&r.theta);
                refined = true;
                for (d, se) in free.iter().zip(&r.std_errors) {
                    if let Some(se) = se {
                        hyper_se.insert(cand.hyper_parameters[*d].name.clone(), *se);
                    }
                }
            }
        }
    }
    let sweeps = if refined {
        0
    } else if free.len() > 1 {
        2
    } else {
        1
    };
    for _ in 0..sweeps {
        for &d in &free {
            let (lo, hi) = bracket(d, best_h[d]);
            let mut eval = |x: f64| -> f64 {
                evaluations += 1;
                let mut h = best_h.clone();
                h[d] = x;
                reduction(p, cand, &h).map(|r| r.0).unwrap_or(f64::NEG_INFINITY)
            };
            let (x, fx) = golden_max(&mut eval, lo, hi, config.refine_iterations);
            if fx > best_red {
                best_red = fx;
                best_h[d] = x;
            }
        }
    }
    let (_, cols) = reduction(p, cand, &best_h).map_err(|e| err(e.to_string()))?;
    // Variable projection: the candidate's coefficients of the joint weighted fit (base +
    // candidate) are those of the base-projected residual on the base-projected columns, with the
    // same covariance block; the weighted new residual is what that fit leaves.
    // (A column dependent on the base is zero: coefficient 0, infinite standard error.)
    let pc = p.base.project_columns(&cols, &p.w);
    let fit = fit_signature(&p.r_t, &pc, &Sigma::Constant(1.0))?;
    let new_residual: Vec<f64> = fit.residual.iter().zip(&p.w).map(|(r, w)| r / w).collect();
    let stat_new: f64 = fit.residual.iter().map(|r| r * r).sum();
    let fitted_change: Vec<f64> = p.r_t.iter().zip(&fit.residual).map(|(rt, r)| rt - r).collect();
    let k = cand.coefficient_names.len() + cand.searched();
    let searched: usize = match cand.chosen_from {
        Some(m) => m,
        None => cand.hyper_parameters.iter().filter(|h| h.grid.len() > 1).map(|h| h.grid.len()).product(),
    };
    let p_value = search_p_value(p, stat_new, candidate_basis(p, &cols).q.len(), p.base.rank(), searched);
    let coefs = &fit.coefficients[..];
    let coefficients: BTreeMap<String, f64> =
        cand.coefficient_names.iter().cloned().zip(coefs.iter().copied()).collect();
    // σ unknown: the scale √(χ²/(n − rank)) counts the base's rank too.
    let se_scale = if p.known {
        1.0
    } else {
        let dof = p.n.saturating_sub(p.base.rank() + fit.rank).max(1) as f64;
        (stat_new / dof).sqrt()
    };
    let std_errors: BTreeMap<String, f64> =
        cand.coefficient_names.iter().cloned().zip(fit.std_errors.iter().map(|s| s * se_scale)).collect();
    let hyper_at_bound: Vec<String> = cand
        .hyper_parameters
        .iter()
        .zip(&best_h)
        .filter(|(h, x)| h.refine && at_grid_end(&h.grid, **x))
        .map(|(h, _)| h.name.clone())
        .collect();
    let hyper_std_errors: BTreeMap<String, f64> =
        hyper_se.into_iter().filter(|(k, _)| !hyper_at_bound.contains(k)).map(|(k, s)| (k, s * se_scale)).collect();
    let hyper_parameters: BTreeMap<String, f64> =
        cand.hyper_parameters.iter().map(|h| h.name.clone()).zip(best_h.iter().copied()).collect();
    let params = match &cand.describe {
        Some(f) => f(coefs, &best_h),
        None => coefficients.iter().chain(hyper_parameters.iter()).map(|(a, b)| (a.clone(), *b)).collect(),
    };
    Ok(CandidateFit {
        effect: cand.effect.clone(),
        coefficients,
        std_errors,
        hyper_std_errors,
        hyper_parameters,
        hyper_at_bound,
        params,
        n: p.n,
        k,
        chi2_old: p.known.then_some(p.stat_old),
        chi2_new: p.known.then_some(stat_new),
        rss_old: p.rss_old,
        rss_new: new_residual.iter().map(|r| r * r).sum(),
        delta_bic: delta_bic(p, stat_new, k),
        explained: (1.0 - stat_new / p.stat_old).clamp(0.0, 1.0),
        conditional_delta_bic: None,
        evaluations,
        searched,
        p_value,
        columns: cols,
        new_residual,
        fitted_change,
    })
}

/// A searched value `x` at an end of `grid` (more than one value): within 1 % of the step from
/// that end to its neighbour ([`CandidateFit::hyper_at_bound`]).
pub fn at_grid_end(grid: &[f64], x: f64) -> bool {
    let mut g = grid.to_vec();
    g.sort_by(f64::total_cmp);
    g.dedup();
    let n = g.len();
    n > 1 && (x <= g[0] + 0.01 * (g[1] - g[0]) || x >= g[n - 1] - 0.01 * (g[n - 1] - g[n - 2]))
}

/// P(χ²_q > Δχ²)·M (module doc): Δχ² = stat_old − stat_new with σ known; with σ's scale free,
/// Δχ²·(n − nb − q)/stat_new (the F statistic times q, χ²_q for large n). 1 when q = 0.
fn search_p_value(p: &Prepared, stat_new: f64, q: usize, nb: usize, searched: usize) -> f64 {
    if q == 0 {
        return 1.0;
    }
    let drop = (p.stat_old - stat_new).max(0.0);
    let x = if p.known {
        drop
    } else {
        let dof = p.n.saturating_sub(nb + q).max(1) as f64;
        drop * dof / stat_new.max(1e-300)
    };
    let tail = super::stats::chi_square_sf(x, q as f64).unwrap_or(1.0);
    (tail * searched.max(1) as f64).min(1.0)
}

/// Golden-section search for the maximum of `f` on [lo, hi] (Kiefer 1953; ratio (√5 − 1)/2, one
/// new evaluation per iteration, at most `iters`); returns (x, f(x)) of the best point evaluated.
/// The one line search of the model-check loop (`vmt::modelcheck` uses it on log scales).
pub fn golden_max(f: &mut impl FnMut(f64) -> f64, lo: f64, hi: f64, iters: usize) -> (f64, f64) {
    golden_max_each(&mut |xs: &[f64]| xs.iter().map(|&x| f(x)).collect(), &[(lo, hi)], iters)[0]
}

/// [`golden_max`] over several intervals `ranges` in lockstep: each round asks `f` for the values
/// at the next point of every search still running, together (a batch whose evaluations can share
/// work, such as one matrix product for all of them). Each search takes the points and returns
/// the (argmax, max) that [`golden_max`] would on its interval alone; `f` must return one value
/// per point, in order.
pub fn golden_max_each(f: &mut impl FnMut(&[f64]) -> Vec<f64>, ranges: &[(f64, f64)], iters: usize) -> Vec<(f64, f64)> {
    /// One search: its bracket [a, b], inner points c < d with their values, best so far.
    struct Search {
        a: f64,
        b: f64,
        c: f64,
        d: f64,
        fc: f64,
        fd: f64,
        best: (f64, f64),
    }
    let gr = (5f64.sqrt() - 1.0) / 2.0;
    let ends: Vec<(f64, f64, f64, f64)> =
        ranges.iter().map(|&(a, b)| (a, b, b - gr * (b - a), a + gr * (b - a))).collect();
    let first = f(&ends.iter().flat_map(|e| [e.2, e.3]).collect::<Vec<f64>>());
    let mut s: Vec<Search> = ends
        .iter()
        .enumerate()
        .map(|(k, &(a, b, c, d))| {
            // index: `first` holds two values per range, in order (f's contract).
            let (fc, fd) = (first[2 * k], first[2 * k + 1]);
            let best = if fc >= fd { (c, fc) } else { (d, fd) };
            Search { a, b, c, d, fc, fd, best }
        })
        .collect();
    let mut running: Vec<usize> = (0..s.len()).collect();
    for _ in 0..iters {
        running.retain(|&k| (s[k].b - s[k].a).abs() > 1e-12 * (s[k].a.abs() + s[k].b.abs()));
        if running.is_empty() {
            break;
        }
        // Each search's next point: a new c after moving b down (fc ≥ fd), else a new d after
        // moving a up; `lower` says which.
        let (points, lower): (Vec<f64>, Vec<bool>) = running
            .iter()
            .map(|&k| {
                let t = &mut s[k];
                if t.fc >= t.fd {
                    (t.b, t.d, t.fd) = (t.d, t.c, t.fc);
                    t.c = t.b - gr * (t.b - t.a);
                    (t.c, true)
                } else {
                    (t.a, t.c, t.fc) = (t.c, t.d, t.fd);
                    t.d = t.a + gr * (t.b - t.a);
                    (t.d, false)
                }
            })
            .unzip();
        let values = f(&points);
        for (((&k, &x), &v), &low) in running.iter().zip(&points).zip(&values).zip(&lower) {
            let t = &mut s[k];
            if low {
                t.fc = v;
            } else {
                t.fd = v;
            }
            if v > t.best.1 {
                t.best = (x, v);
            }
        }
    }
    s.iter().map(|t| t.best).collect()
}

/// Brent's minimisation on [lo, hi] without derivatives (Brent 1973, *Algorithms for Minimization
/// without Derivatives*, ch. 5): golden-section steps, and a parabola through the three best
/// points where it falls well inside the bracket, so that a smooth minimum is reached
/// superlinearly. It stops when the best point x is within 2·tol₁ of the bracket's ends around it,
/// tol₁ = √ε·|x| + `tol`/3 (ε the f64 epsilon: near a minimum f changes by about (δx)²·f''/2, so x
/// is not resolved better than √ε relative), or after `max_evals` evaluations of `f`. Returns (x,
/// f(x)) of the best point evaluated. A search that golden section (ratio 0.618 per evaluation)
/// took 42 evaluations for, a smooth minimum inside a bracket of 0.46, takes 10–15.
pub fn brent_min(f: &mut impl FnMut(f64) -> f64, lo: f64, hi: f64, tol: f64, max_evals: usize) -> (f64, f64) {
    brent_min_each(&mut |xs: &[f64]| xs.iter().map(|&x| f(x)).collect(), &[(lo, hi)], tol, max_evals)[0]
}

/// [`brent_min`] over several intervals `ranges` in lockstep: each round asks `f` for the values
/// at the next point of every search still running, together (a batch whose evaluations can share
/// work), and returns one value per point, in order. Each search takes the points and returns the
/// (argmin, min) that [`brent_min`] would on its interval alone.
pub fn brent_min_each(
    f: &mut impl FnMut(&[f64]) -> Vec<f64>,
    ranges: &[(f64, f64)],
    tol: f64,
    max_evals: usize,
) -> Vec<(f64, f64)> {
    let mut s: Vec<BrentSearch> = ranges.iter().map(|&(lo, hi)| BrentSearch::new(lo, hi, tol)).collect();
    let first = f(&s.iter().map(|t| t.x).collect::<Vec<f64>>());
    // index: `first` holds one value per range, in order (f's contract).
    s.iter_mut().zip(first).for_each(|(t, fx)| (t.fx, t.fw, t.fv) = (fx, fx, fx));
    for _ in 1..max_evals {
        let next: Vec<(usize, f64)> = s.iter_mut().enumerate().filter_map(|(k, t)| t.next().map(|u| (k, u))).collect();
        if next.is_empty() {
            break;
        }
        let values = f(&next.iter().map(|&(_, u)| u).collect::<Vec<f64>>());
        for (&(k, u), fu) in next.iter().zip(values) {
            s[k].update(u, fu);
        }
    }
    s.iter().map(|t| (t.x, t.fx)).collect()
}

/// One search of [`brent_min_each`]: the bracket [a, b]; x the best point, w the second best, v
/// the previous w, with their values; d the last step and e the one before; `done` once x is
/// settled.
struct BrentSearch {
    a: f64,
    b: f64,
    x: f64,
    w: f64,
    v: f64,
    fx: f64,
    fw: f64,
    fv: f64,
    d: f64,
    e: f64,
    tol: f64,
    done: bool,
}

impl BrentSearch {
    /// The search on [lo, hi], its first point x at the golden section of the bracket.
    fn new(lo: f64, hi: f64, tol: f64) -> BrentSearch {
        let (a, b) = if lo <= hi { (lo, hi) } else { (hi, lo) };
        let x = a + BRENT_GOLDEN * (b - a);
        let nan = f64::NAN;
        BrentSearch { a, b, x, w: x, v: x, fx: nan, fw: nan, fv: nan, d: 0.0, e: 0.0, tol, done: false }
    }

    /// The next point to evaluate, or None once x is within 2·tol₁ of the bracket's ends around it.
    fn next(&mut self) -> Option<f64> {
        if self.done {
            return None;
        }
        let Self { a, b, x, w, v, fx, fw, fv, .. } = *self;
        let m = 0.5 * (a + b);
        let tol1 = f64::EPSILON.sqrt() * x.abs() + self.tol / 3.0;
        let tol2 = 2.0 * tol1;
        if (x - m).abs() <= tol2 - 0.5 * (b - a) {
            self.done = true;
            return None;
        }
        // A parabola through (v, fv), (w, fw), (x, fx): its step p/q from x.
        let (mut p, mut q, mut r) = (0.0, 0.0, 0.0);
        if self.e.abs() > tol1 {
            r = (x - w) * (fx - fv);
            q = (x - v) * (fx - fw);
            p = (x - v) * q - (x - w) * r;
            q = 2.0 * (q - r);
            if q > 0.0 {
                p = -p;
            } else {
                q = -q;
            }
            r = self.e;
            self.e = self.d;
        }
        if p.abs() < (0.5 * q * r).abs() && p > q * (a - x) && p < q * (b - x) {
            // The parabola's step, kept tol₂ away from the ends.
            self.d = p / q;
            let u = x + self.d;
            if u - a < tol2 || b - u < tol2 {
                self.d = if x < m { tol1 } else { -tol1 };
            }
        } else {
            // A golden-section step into the larger part.
            self.e = if x < m { b - x } else { a - x };
            self.d = BRENT_GOLDEN * self.e;
        }
        let d = self.d;
        Some(if d.abs() >= tol1 { x + d } else { x + tol1.copysign(d) })
    }

    /// The bracket and the three best points after f(u) = fu.
    fn update(&mut self, u: f64, fu: f64) {
        if fu <= self.fx {
            if u < self.x {
                self.b = self.x;
            } else {
                self.a = self.x;
            }
            (self.v, self.fv, self.w, self.fw, self.x, self.fx) = (self.w, self.fw, self.x, self.fx, u, fu);
        } else {
            if u < self.x {
                self.a = u;
            } else {
                self.b = u;
            }
            if fu <= self.fw || self.w == self.x {
                (self.v, self.fv, self.w, self.fw) = (self.w, self.fw, u, fu);
            } else if fu <= self.fv || self.v == self.x || self.v == self.w {
                (self.v, self.fv) = (u, fu);
            }
        }
    }
}

/// (3 − √5)/2: the golden section of a bracket, from its nearer end.
const BRENT_GOLDEN: f64 = 0.381_966_011_250_105_1;

fn cosine(a: &[f64], b: &[f64]) -> f64 {
    let ab: f64 = a.iter().zip(b).map(|(x, y)| x * y).sum();
    let aa: f64 = a.iter().map(|x| x * x).sum();
    let bb: f64 = b.iter().map(|x| x * x).sum();
    if aa == 0.0 || bb == 0.0 {
        0.0
    } else {
        (ab / (aa * bb).sqrt()).abs()
    }
}

/// Ranks candidate effects for the residual (FORMAT.md §4 `ranking`, best first, every candidate
/// listed).
///
/// Each candidate is fitted alone (plus the base columns) by [`fit_candidate`]; `delta_bic` and
/// `explained` in the ranking are these marginal values, and the list is sorted by `delta_bic`.
/// Verdicts:
/// 1. *marginally significant*: ΔBIC < `significance_threshold` and explained ≥ `explained_floor`;
/// 2. *inseparable*: two marginally significant candidates whose fitted changes
///    W^{1/2}(r_old − r_new) have |cos| > `collinearity_cosine` and whose ΔBIC differ by less
///    than `inseparable_margin`; both list each other in `confused_with`;
/// 3. *significant*: going down the list, a marginally significant, not inseparable candidate
///    stays significant only if its ΔBIC conditional on the already accepted candidates (and one
///    representative of each inseparable group met so far) is still below the threshold — so an
///    effect that is merely correlated with the true one is "explained away" and reported as
///    `noise` (its conditional ΔBIC is in [`CandidateFit::conditional_delta_bic`]);
/// 4. *noise*: everything else.
pub fn rank_candidates(
    input: &ResidualInput,
    candidates: &[Candidate],
    config: &DiagnoseConfig,
) -> Result<Diagnosis, ModelCheckError> {
    let refs: Vec<&Candidate> = candidates.iter().collect();
    rank_refs(input, &refs, config)
}

fn rank_refs(
    input: &ResidualInput,
    candidates: &[&Candidate],
    config: &DiagnoseConfig,
) -> Result<Diagnosis, ModelCheckError> {
    if candidates.is_empty() {
        return Err(ModelCheckError::Invalid("diagnose: no candidate effects to try".into()));
    }
    let p = prepare(input)?;
    let mut fits: Vec<CandidateFit> =
        candidates.par_iter().map(|c| fit_prepared(&p, c, config)).collect::<Result<_, _>>()?;
    fits.sort_by(|a, b| a.delta_bic.total_cmp(&b.delta_bic).then_with(|| a.effect.cmp(&b.effect)));
    let m = fits.len();
    // Bonferroni over the C candidates ranked: the whole diagnosis's false-alarm bound.
    for f in fits.iter_mut() {
        f.p_value = (f.p_value * m as f64).min(1.0);
    }
    let marginal: Vec<bool> = fits
        .iter()
        .map(|f| {
            f.delta_bic < config.significance_threshold
                && f.explained >= config.explained_floor
                && f.p_value <= config.family_alpha
        })
        .collect();
    let mut confused: Vec<Vec<String>> = vec![Vec::new(); m];
    for a in 0..m {
        for b in a + 1..m {
            if marginal[a]
                && marginal[b]
                && (fits[a].delta_bic - fits[b].delta_bic).abs() < config.inseparable_margin
                && cosine(&fits[a].fitted_change, &fits[b].fitted_change) > config.collinearity_cosine
            {
                let (ea, eb) = (fits[a].effect.clone(), fits[b].effect.clone());
                confused[a].push(eb);
                confused[b].push(ea);
            }
        }
    }
    let mut verdicts = vec![Verdict::Noise; m];
    // Columns accepted so far beyond the base (significant + inseparable representatives); the
    // conditional fits extend the base's factorisation by them (`OrthoBase::extended`).
    let mut accepted: Vec<Vec<f64>> = Vec::new();
    let mut represented: Vec<bool> = vec![false; m];
    for a in 0..m {
        if !marginal[a] {
            continue;
        }
        if !confused[a].is_empty() {
            verdicts[a] = Verdict::Inseparable;
            // The first member of a group met in rank order represents the group.
            let group_seen = (0..a).any(|b| represented[b] && confused[a].contains(&fits[b].effect));
            if !group_seen {
                represented[a] = true;
                accepted.extend(fits[a].columns.iter().cloned());
            }
            continue;
        }
        let cond = if accepted.is_empty() {
            fits[a].delta_bic
        } else {
            match prepared_on(input, p.w.clone(), p.base.extended(&accepted, &p.w)?) {
                // The accepted candidates explain everything: this one adds only its penalty.
                Err(ModelCheckError::NothingToExplain) => fits[a].k as f64 * (p.n as f64).ln(),
                Err(e) => return Err(e),
                Ok(cp) => {
                    let stat_new = (cp.stat_old - reduction_of(&cp, &fits[a].columns)).max(0.0);
                    delta_bic(&cp, stat_new, fits[a].k)
                }
            }
        };
        fits[a].conditional_delta_bic = Some(cond);
        if cond < config.significance_threshold {
            verdicts[a] = Verdict::Significant;
            represented[a] = true;
            accepted.extend(fits[a].columns.iter().cloned());
        }
    }
    let ranking = fits
        .iter()
        .zip(verdicts)
        .zip(confused)
        .map(|((f, verdict), confused_with)| RankingEntry {
            effect: f.effect.clone(),
            delta_bic: f.delta_bic,
            explained: f.explained,
            verdict,
            params: f.params.clone(),
            confused_with,
            note: None,
            aliases: vec![],
            p_value: Some(f.p_value),
            searched: Some(f.searched),
            at_bound: f.hyper_at_bound.clone(),
            shape_orders: BTreeMap::new(),
        })
        .collect();
    Ok(Diagnosis { ranking, fits, stat_old: p.stat_old, n: p.n })
}

/// Result of [`forward_select`].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ForwardSelection {
    /// The effects added, in order, each with the ΔBIC conditional on the ones before it.
    pub selected: Vec<RankingEntry>,
    /// The ranking at each step (step i is conditional on the first i selected effects).
    pub steps: Vec<Diagnosis>,
    /// Why the selection stopped.
    pub stop_reason: String,
}

/// Greedy forward selection (for residuals with several missing effects): rank the candidates
/// ([`rank_candidates`]); if the best is `significant`, add its columns (hyper-parameters held
/// at their fitted values) to the base columns, remove it from the candidates and repeat; stop
/// when the best is `noise` or `inseparable` (the data cannot choose), when no candidate is
/// left, when the residual is explained exactly, or after `config.max_steps` additions.
pub fn forward_select(
    input: &ResidualInput,
    candidates: &[Candidate],
    config: &DiagnoseConfig,
) -> Result<ForwardSelection, ModelCheckError> {
    let mut base: Vec<Vec<f64>> = input.base_columns.to_vec();
    let mut remaining: Vec<&Candidate> = candidates.iter().collect();
    let mut selected = Vec::new();
    let mut steps = Vec::new();
    let stop_reason = loop {
        if remaining.is_empty() {
            break "every candidate was selected".to_string();
        }
        if selected.len() >= config.max_steps {
            break format!("reached the maximum of {} effects", config.max_steps);
        }
        let step_input = ResidualInput { residual: input.residual, sigma: input.sigma, base_columns: &base };
        let diag = match rank_refs(&step_input, &remaining, config) {
            Err(ModelCheckError::NothingToExplain) if !selected.is_empty() => {
                break "the selected effects explain the residual exactly".to_string();
            }
            other => other?,
        };
        let top = diag.ranking[0].clone();
        let cols = diag.fits[0].columns.clone();
        steps.push(diag);
        match top.verdict {
            Verdict::Significant => {
                base.extend(cols);
                remaining.retain(|c| c.effect != top.effect);
                selected.push(top);
            }
            Verdict::Inseparable => {
                break format!(
                    "the best candidates cannot be separated with this data: {} and {}",
                    top.effect,
                    top.confused_with.join(", ")
                );
            }
            Verdict::Noise => break "no remaining candidate is significant".to_string(),
        }
    };
    Ok(ForwardSelection { selected, steps, stop_reason })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Brent's minimisation finds the minimum of a smooth function on a log-scale bracket (the
    /// residual sum of a loop gain: a quartic well in ln kv, minimum off the bracket's centre) to
    /// √ε relative in at most 16 evaluations, where golden section took 42; a minimum at an end
    /// of the bracket is approached to within the tolerance; a linear function's at its low end.
    #[test]
    fn brent_finds_a_smooth_minimum_in_few_evaluations() {
        let at = 32.123_f64.ln();
        for (lo, hi) in [(25.0_f64.ln(), 40.0_f64.ln()), (30.0_f64.ln(), 33.0_f64.ln())] {
            let mut evals = 0;
            let (x, fx) = brent_min(
                &mut |x: f64| {
                    evals += 1;
                    1e4 * (x - at).powi(2) + 3e5 * (x - at).powi(4) + 17.0
                },
                lo,
                hi,
                1e-10,
                60,
            );
            assert!((x - at).abs() < 1e-7, "{x} vs {at}");
            assert!((fx - 17.0).abs() < 1e-9);
            assert!(evals <= 16, "{evals} evaluations");
        }
        let (x, _) = brent_min(&mut |x: f64| (x - 5.0).powi(2), 0.0, 2.0, 1e-10, 60);
        assert!((x - 2.0).abs() < 1e-6, "{x}");
        let (x, _) = brent_min(&mut |x: f64| x, -1.0, 1.0, 1e-10, 60);
        assert!((x + 1.0).abs() < 1e-6, "{x}");
    }

    #[test]
    fn verdict_serialises_lowercase_and_entry_has_format_keys() {
        let e = RankingEntry {
            effect: "backlash".into(),
            delta_bic: -812.0,
            explained: 0.91,
            verdict: Verdict::Significant,
            params: [("value".to_string(), 6.1e-6)].into_iter().collect(),
            confused_with: vec![],
            note: None,
            aliases: vec![],
            p_value: None,
            searched: None,
            at_bound: vec![],
            shape_orders: BTreeMap::new(),
        };
        let s = serde_json::to_string(&e).unwrap();
        assert_eq!(
            s,
            r#"{"effect":"backlash","delta_bic":-812.0,"explained":0.91,"verdict":"significant","params":{"value":6.1e-6},"confused_with":[]}"#
        );
    }

    #[test]
    fn golden_section_finds_parabola_maximum() {
        let (x, fx) = golden_max(&mut |x| -(x - 0.3).powi(2), 0.0, 1.0, 60);
        // 60 iterations shrink the bracket by 0.618^60 ≈ 3e-13.
        assert!((x - 0.3).abs() < 1e-7 && fx <= 0.0);
    }

    /// Five intervals of different widths (disjoint, so that each point names its search) and a
    /// function on each, with its maximum inside or at an end; one interval so narrow that its
    /// search stops before the others.
    const LOCKSTEP_RANGES: [(f64, f64); 5] = [(0.0, 1.0), (-3.0, -0.5), (10.0, 10.0 + 1e-9), (1.2, 1.9), (20.0, 60.0)];

    fn lockstep_f(k: usize, x: f64) -> f64 {
        match k {
            0 => -(x - 0.3).powi(2),
            1 => (x * 1.7).sin() - 0.1 * x * x + x,
            2 => -(x - 10.0).abs(),
            3 => x.powi(3),
            _ => -(x.ln() - 3.5).powi(2) + 0.01 * (5.0 * x).cos(),
        }
    }

    /// A batch of points of [`LOCKSTEP_RANGES`]' searches, each valued by its search's function
    /// times `sign`; counts the batches.
    fn lockstep_batch(xs: &[f64], sign: f64, calls: &mut usize) -> Vec<f64> {
        *calls += 1;
        xs.iter()
            .map(|&x| sign * lockstep_f(LOCKSTEP_RANGES.iter().position(|&(a, b)| x >= a && x <= b).unwrap(), x))
            .collect()
    }

    /// Searches in lockstep ([`golden_max_each`]) end where each alone ends ([`golden_max`]), to the
    /// bit, on [`LOCKSTEP_RANGES`]; one batch per round.
    #[test]
    fn golden_searches_in_lockstep_end_where_each_alone_ends() {
        let alone: Vec<(f64, f64)> = LOCKSTEP_RANGES
            .iter()
            .enumerate()
            .map(|(k, &(a, b))| golden_max(&mut |x| lockstep_f(k, x), a, b, 40))
            .collect();
        let mut calls = 0;
        let together = golden_max_each(&mut |xs: &[f64]| lockstep_batch(xs, 1.0, &mut calls), &LOCKSTEP_RANGES, 40);
        assert_eq!(alone, together);
        assert!(calls <= 41, "{calls} batches");
    }

    /// Brent's searches in lockstep ([`brent_min_each`]) end where each alone ends ([`brent_min`]),
    /// to the bit, on [`LOCKSTEP_RANGES`] (the functions negated); one batch per round, at most
    /// the 41 of golden section (an optimum at an end of its bracket, x³ here, is approached by
    /// golden-section steps alone: 34 rounds).
    #[test]
    fn brent_searches_in_lockstep_end_where_each_alone_ends() {
        let alone: Vec<(f64, f64)> = LOCKSTEP_RANGES
            .iter()
            .enumerate()
            .map(|(k, &(a, b))| brent_min(&mut |x| -lockstep_f(k, x), a, b, 1e-10, 41))
            .collect();
        let mut calls = 0;
        let together =
            brent_min_each(&mut |xs: &[f64]| lockstep_batch(xs, -1.0, &mut calls), &LOCKSTEP_RANGES, 1e-10, 41);
        assert_eq!(alone, together);
        assert!(calls <= 41, "{calls} batches");
    }

    #[test]
    fn noise_free_step_is_recovered_exactly() {
        let dir: Vec<f64> = (0..40).map(|i| if i % 2 == 0 { 0.5 } else { -0.5 }).collect();
        let r: Vec<f64> = dir.iter().map(|d| 6e-6 * d + 1e-6).collect();
        let base = vec![vec![1.0; 40]];
        let d2 = dir.clone();
        let cands = vec![Candidate::new("backlash", &["value"], move |_| Ok(vec![d2.clone()]))];
        let inp = ResidualInput { residual: &r, sigma: &Sigma::Constant(1e-7), base_columns: &base };
        let d = rank_candidates(&inp, &cands, &DiagnoseConfig::default()).unwrap();
        assert_eq!(d.ranking[0].verdict, Verdict::Significant);
        assert!((d.ranking[0].params["value"] - 6e-6).abs() < 1e-15);
        assert!(d.ranking[0].explained > 1.0 - 1e-12);
        let fs = forward_select(&inp, &cands, &DiagnoseConfig::default()).unwrap();
        assert_eq!(fs.selected.len(), 1);
        assert_eq!(fs.stop_reason, "every candidate was selected");
        let d3 = dir.clone();
        let two = vec![
            Candidate::new("backlash", &["value"], move |_| Ok(vec![d3.clone()])),
            Candidate::new("scale_error", &["value"], |_| Ok(vec![(0..40).map(|i| i as f64).collect()])),
        ];
        let fs = forward_select(&inp, &two, &DiagnoseConfig::default()).unwrap();
        assert_eq!(fs.stop_reason, "the selected effects explain the residual exactly");
        // Bad input is an error, not a panic.
        let bad = vec![Candidate::new("bad", &["a"], |_| Ok(vec![vec![1.0; 3]]))];
        let e = rank_candidates(&inp, &bad, &DiagnoseConfig::default()).unwrap_err();
        assert!(e.to_string().contains("must have 40 values (one per sample), got 3"), "{e}");
    }

    /// A candidate that also gives its columns as runs ([`Candidate::with_sparse`]) is searched on
    /// them to the same best grid point and fit as from its dense columns alone (a pulse of unknown
    /// start on 60 samples, its grid of 40 starts); runs that do not fit the rows are an error
    /// naming the column and rows, not a panic.
    #[test]
    fn sparse_signature_searches_as_the_dense_one() {
        let n = 60;
        let pulse = |at: f64| -> Vec<f64> {
            (0..n).map(|i| if (i as f64) >= at && (i as f64) < at + 12.0 { 1.0 } else { 0.0 }).collect()
        };
        let r: Vec<f64> =
            pulse(23.0).iter().enumerate().map(|(i, p)| 3e-6 * p + 1e-8 * ((i * 7 % 5) as f64 - 2.0)).collect();
        let base = vec![vec![1.0; n]];
        let inp = ResidualInput { residual: &r, sigma: &Sigma::Constant(1e-8), base_columns: &base };
        let grid: Vec<f64> = (0..40).map(|k| k as f64 + 0.5).collect();
        let dense = || {
            Candidate::new("pulse", &["height"], move |h: &[f64]| Ok(vec![pulse(h[0])])).with_hyper("at", grid.clone())
        };
        let runs = |h: &[f64]| -> Vec<SparseColumn> {
            let lo = h[0].ceil() as usize;
            vec![SparseColumn { runs: vec![(lo, vec![1.0; 12.min(n - lo)])] }]
        };
        let config = DiagnoseConfig::default();
        let a = rank_candidates(&inp, &[dense()], &config).unwrap();
        let b = rank_candidates(&inp, &[dense().with_sparse(move |h: &[f64]| Ok(runs(h)))], &config).unwrap();
        assert_eq!(a.ranking[0].params, b.ranking[0].params);
        assert_eq!(a.ranking[0].delta_bic, b.ranking[0].delta_bic);
        assert!((a.ranking[0].params["at"] - 23.0).abs() <= 1.0, "{:?}", a.ranking[0].params);
        let past = dense().with_sparse(|_: &[f64]| Ok(vec![SparseColumn { runs: vec![(55, vec![1.0; 12])] }]));
        let e = rank_candidates(&inp, &[past], &config).unwrap_err();
        assert!(e.to_string().contains("signature column 0: a run at rows 55..67"), "{e}");
    }

    /// The Gram-matrix projection of the screen equals the orthogonalised one (MGS, `Basis`) to
    /// 1e-9 relative, with local columns (non-zero on part of the rows) and one column dependent
    /// on two others (dropped, not counted twice).
    #[test]
    fn span_projection_matches_orthogonal_basis() {
        let n = 200;
        let x: Vec<f64> = (0..n).map(|i| i as f64 / n as f64).collect();
        let a: Vec<f64> = x.iter().map(|v| if *v < 0.5 { (9.0 * v).sin() } else { 0.0 }).collect();
        let b: Vec<f64> = x.iter().map(|v| if *v > 0.3 { (4.0 * v).cos() } else { 0.0 }).collect();
        let c: Vec<f64> = x.iter().map(|v| v * v).collect();
        let dep: Vec<f64> = a.iter().zip(&b).map(|(p, q)| 2.0 * p - 0.5 * q).collect();
        let w: Vec<f64> = x.iter().map(|v| 1.0 + v).collect();
        let r: Vec<f64> = x.iter().map(|v| (17.0 * v).sin() + v).collect();
        let cols = vec![a, b, dep, c];
        let mut basis = Basis::default();
        for col in &cols {
            basis.push(col.iter().zip(&w).map(|(p, q)| p * q).collect());
        }
        let want: f64 = basis.q.iter().map(|q| q.iter().zip(&r).map(|(p, q)| p * q).sum::<f64>().powi(2)).sum();
        let got = span_projection(&cols, &w, &r);
        assert_eq!(basis.q.len(), 3);
        assert!((got - want).abs() <= 1e-9 * want, "{got} vs {want}");
    }
}
