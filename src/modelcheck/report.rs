//! Reports: compare and diagnose.

use super::*;
use rayon::prelude::*;
use vmt_sim::effects::InterpolationError;

// ------------------------------------------------------------------------------------------
// Reports.

/// One channel of `vmt compare` (FORMAT.md §4 `channels[]`, plus details).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ChannelReport {
    /// Run name.
    pub run: String,
    /// SI unit of the channel's values (`m` for deviations, `N` for motor forces).
    pub unit: String,
    /// Sensor name.
    pub sensor: String,
    /// RMS of the residual, SI unit of the channel (m).
    pub rms: f64,
    /// RMS of residual/σ, each sample's σ: the channel's `sigma`, with a command's reading
    /// uncertainty added in quadrature on a following channel ([`st_sigma`]).
    pub normalized_rms: f64,
    /// NRMSE fit, % : 100·(1 − ‖y − ŷ‖/‖y − ȳ‖).
    pub fit_percent: f64,
    /// The σ used, m.
    pub sigma: f64,
    /// True when σ was estimated from the residual (the manifest gives none).
    pub sigma_estimated: bool,
    /// Fitted offset (instrument zero), m.
    pub offset: f64,
    /// Fraction of autocorrelation lags outside ±1.96/√n (white: about 5 %).
    pub acf_fraction_outside: Option<f64>,
    /// Ljung–Box p-value of the residual in acquisition order (small: not white).
    pub ljung_box_p: Option<f64>,
    /// Residual by approach direction: (direction, mean, rms).
    pub by_direction: Vec<(i8, f64, f64)>,
    /// Residual by run number (cycle): (cycle, mean, rms).
    pub by_cycle: Vec<(u32, f64, f64)>,
    /// Residual by position bin: (lower, upper, mean, rms), m.
    pub by_position: Vec<(f64, f64, f64, f64)>,
    /// Residual by time bin: (lower, upper, mean, rms), s.
    pub by_time: Vec<(f64, f64, f64, f64)>,
    /// Strongest spatial periods of the residual: (wavelength m, amplitude m), from a
    /// least-squares periodogram over position.
    pub spectrum_peaks: Vec<(f64, f64)>,
    /// The residual's whole least-squares periodogram (`ls_periodogram`, σ unknown, 5× oversampled up
    /// to the pseudo-Nyquist frequency): (frequency, amplitude in the channel's SI unit), over the
    /// session time in Hz for accelerometer channels (a resonance lives in time), over the position in
    /// cycles per m for the others (cyclic errors live in space). Empty when the channel has too few
    /// distinct coordinates. Not written to JSON (thousands of values per channel); reports draw it.
    #[serde(skip)]
    pub spectrum: Vec<(f64, f64)>,
}

/// One iteration of the loop, as kept in `history.json`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct HistoryEntry {
    /// Model file.
    pub model: String,
    /// Data it was compared with.
    pub data: String,
    /// Effect added to reach it (empty for the starting model).
    pub added: String,
    /// Normalised RMS of the residual.
    pub normalized_rms: f64,
}

/// `vmt compare` (FORMAT.md §4; extra keys allowed).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct CompareReport {
    /// Model file.
    pub model: String,
    /// Data directory.
    pub data: String,
    /// Per channel.
    pub channels: Vec<ChannelReport>,
    /// RMS of residual/σ over all samples of all channels.
    pub normalized_rms: f64,
    /// Fitted parameters by effect.
    /// Inner keys are FORMAT.md §2 parameter keys and the series coefficients and per-sensor gains
    /// (`p3`, `gain_acc`): no fixed set, as the ranking's `params`.
    pub fitted: EffectMap<BTreeMap<String, f64>>,
    /// Number of samples.
    pub n: usize,
    /// Number of fitted parameters (offsets included).
    pub n_params: usize,
    /// What was skipped or estimated.
    pub notes: Vec<String>,
    /// Iterations so far (history.json beside the model), if any.
    pub history: Vec<HistoryEntry>,
    /// Per fitted error motion: basis, order and why (FORMAT.md §4 `shapes`, optional).
    #[serde(default, skip_serializing_if = "EffectMap::is_empty")]
    pub shapes: EffectMap<ShapeReport>,
    /// The stated σ checked against the repeated readings (FORMAT.md §4 `sigma`, optional).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub sigma: Option<SigmaCheck>,
    /// Per fitted effect, its searched hyper-parameters whose value ended at a limit of the range
    /// searched (optional `at_bound`, docs/formats.md): bounds of the search, not estimates.
    #[serde(default, skip_serializing_if = "EffectMap::is_empty")]
    pub at_bound: EffectMap<Vec<Hyper>>,
}

/// The note of hyper-parameters `names` at a limit of the range searched: bounds, not estimates.
pub(crate) fn bound_note(names: &[Hyper]) -> String {
    format!(
        "{} ended at a limit of the range searched: the fit still improves towards it, so the value is a bound of the \
         search, not an estimate (no standard error)",
        names.iter().map(|n| format!("`{}`", n.as_str())).collect::<Vec<_>>().join(" and ")
    )
}

/// Per fitted term of `fs`, its hyper-parameters at a limit of their search.
pub(crate) fn fit_at_bound(fs: &FitState) -> EffectMap<Vec<Hyper>> {
    fs.terms
        .iter()
        .filter_map(|t| {
            let names: Vec<Hyper> =
                t.shape.hypers.iter().zip(&t.at_bound).filter(|(_, b)| **b).map(|(h, _)| *h).collect();
            (!names.is_empty()).then_some((t.name, names))
        })
        .collect()
}

/// How a fitted error motion's shape was set (FORMAT.md §4 `shapes`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ShapeReport {
    /// The basis, written by its name: `legendre` (Legendre polynomials of the position mapped onto
    /// [−1, 1] over the range of the sample positions, no constant term), `cosine`
    /// (cos(kπ(x − a)/(b − a)), k ≥ 1, for a motion seen only by accelerometers), or the model's
    /// `bspline`, `harmonics`, `table`.
    pub basis: ShapeBasis,
    /// Highest Legendre degree used.
    pub order: u32,
    /// Why this order: `BIC over 1..N`, `model` (the model's `order`) or `default`.
    pub chosen_by: String,
    /// The order BIC prefers on these data when the model gives one (optional).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub bic_order: Option<u32>,
    /// A sparse cosine series: the number of its terms of 1..=`order` fitted, chosen by BIC after
    /// ranking the terms by their own explained χ² (optional; absent when every order up to
    /// `order` is fitted).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub terms: Option<usize>,
}

/// The `shapes` of a fit (see [`ShapeReport`]).
pub(crate) fn shape_reports(fs: &FitState) -> EffectMap<ShapeReport> {
    fs.shapes
        .iter()
        .map(|c| {
            let mut chosen_by = match (c.given, c.max) {
                (true, _) => "model".to_string(),
                (false, Some(m)) if c.terms.is_some() => {
                    format!("BIC over the terms of 1..{m} ranked by their explained chi-square")
                }
                (false, Some(m)) => format!("BIC over 1..{m}"),
                (false, None) => "default".to_string(),
            };
            if c.pinned {
                chosen_by += "; constant and slope pinned at 0 (accelerometers do not see them)";
            }
            match c.lead_cap.filter(|_| !c.given) {
                Some(l) if l.in_model => {
                    chosen_by += &format!(
                        "; at most {} so that the shortest wavelength 2L/K stays longer than the cyclic lead's \
                         {} mm period",
                        l.order,
                        fmt_num(l.period * 1e3)
                    );
                    if l.free_best > l.order {
                        chosen_by += &format!(" (BIC without that cap: order {})", l.free_best);
                    }
                }
                Some(l) if l.free_best > l.order => {
                    chosen_by += &format!(
                        "; orders above {} have wavelengths down to the cyclic-lead periods searched (≤ {} mm): \
                         diagnose ranks a lead against order {}",
                        l.order,
                        fmt_num(l.period * 1e3),
                        l.capped_best
                    );
                }
                Some(_) | None => {}
            }
            let bic_order = (c.given && c.max.is_some()).then_some(c.best);
            let r = ShapeReport { basis: c.basis, order: c.order, chosen_by, bic_order, terms: c.terms };
            (c.name, r)
        })
        .collect()
}

/// `vmt diagnose` (FORMAT.md §4).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct DiagnoseReport {
    /// Normalised RMS of the model's residual.
    pub normalized_rms: f64,
    /// Candidates, best first.
    pub ranking: Vec<RankedEffect>,
    /// What to do next.
    pub advice: String,
    /// Notes (skipped channels, estimated σ).
    pub notes: Vec<String>,
    /// Per fitted error motion of the model: basis, order and why (FORMAT.md §4 `shapes`, optional).
    #[serde(default, skip_serializing_if = "EffectMap::is_empty")]
    pub shapes: EffectMap<ShapeReport>,
    /// The stated σ checked against the repeated readings (FORMAT.md §4 `sigma`, optional).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub sigma: Option<SigmaCheck>,
}

/// One candidate of a diagnosis, ranked (FORMAT.md §4 `ranking`): the estimator's
/// [`vmt_estimators::modelcheck::RankingEntry`] with its names as the catalogue's types (the
/// estimator knows candidates by name only). Written with the same keys and names.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct RankedEffect {
    /// The candidate effect.
    pub effect: EffectName,
    /// ΔBIC of adding the effect alone (negative favours the effect).
    pub delta_bic: f64,
    /// Explained fraction 1 − RSS_new/RSS_old (weighted by 1/σ² when σ is known).
    pub explained: f64,
    /// The verdict.
    pub verdict: Verdict,
    /// Fitted coefficients and hyper-parameters by name, SI units (error-motion series
    /// coefficients `cK`, `p_K` and gains per sensor among them: no fixed set of keys).
    pub params: BTreeMap<String, f64>,
    /// Effects this one is inseparable from (other candidates, or the fitted shapes).
    pub confused_with: Vec<EffectName>,
    /// Why the candidate was not tried or cannot be seen in this data (optional `note`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub note: Option<String>,
    /// Other periods (m) that fit exactly as well on these sample positions (optional `aliases`).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub aliases: Vec<f64>,
    /// Upper bound of the probability that noise alone gives some candidate of this diagnosis a
    /// reduction this large, searches counted (optional `p_value`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub p_value: Option<f64>,
    /// Number of hyper-parameter values searched for this candidate (optional `searched`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub searched: Option<usize>,
    /// Searched hyper-parameters whose best value lies at an end of the range searched (optional
    /// `at_bound`): a bound, not an estimate.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub at_bound: Vec<Hyper>,
    /// The orders of the model's fitted shapes with this candidate in the model, re-chosen by BIC
    /// (optional `shape_orders`).
    #[serde(default, skip_serializing_if = "EffectMap::is_empty")]
    pub shape_orders: EffectMap<u32>,
}

impl RankedEffect {
    /// The estimator's entry with its names typed: effects by [`EffectName`]'s `FromStr`,
    /// hyper-parameters by [`Hyper::named`]. The estimator returns the names the candidates were
    /// made with, so a name that is neither is an internal error.
    pub(crate) fn typed(r: RankingEntry) -> Result<RankedEffect, RankingNameError> {
        let effect = |s: &str| s.parse::<EffectName>().map_err(|_| RankingNameError::Effect(s.to_string()));
        let hyper = |s: &str| Hyper::named(s).ok_or_else(|| RankingNameError::Hyper(s.to_string()));
        Ok(RankedEffect {
            effect: effect(&r.effect)?,
            delta_bic: r.delta_bic,
            explained: r.explained,
            verdict: r.verdict,
            params: r.params,
            confused_with: r.confused_with.iter().map(|s| effect(s)).collect::<Result<_, _>>()?,
            note: r.note,
            aliases: r.aliases,
            p_value: r.p_value,
            searched: r.searched,
            at_bound: r.at_bound.iter().map(|s| hyper(s)).collect::<Result<_, _>>()?,
            shape_orders: r.shape_orders.iter().map(|(k, o)| Ok((effect(k)?, *o))).collect::<Result<_, _>>()?,
        })
    }
}

/// A name in the estimator's ranking that is not one of vmt's ([`RankedEffect::typed`]): an
/// internal error, the estimator returns the names the candidates were made with.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum RankingNameError {
    /// Not an effect of the catalogue.
    #[error("the estimator's ranking names an effect `{0}` the catalogue does not have")]
    Effect(String),
    /// Not a hyper-parameter vmt searches ([`Hyper`]).
    #[error("the estimator's ranking names a hyper-parameter `{0}` vmt does not search")]
    Hyper(String),
}

/// A map keyed by effect that iterates, and is written, in the order of the effects' names, as the
/// files have it (`pitch` before `roll`; a `BTreeMap<EffectName, _>` iterates in catalogue order).
/// Serialised as a JSON object keyed by the names.
#[derive(Clone, Debug, PartialEq)]
pub struct EffectMap<V>(Vec<(EffectName, V)>);

impl<V> Default for EffectMap<V> {
    fn default() -> Self {
        EffectMap(Vec::new())
    }
}

impl<V> EffectMap<V> {
    /// An empty map.
    pub fn new() -> Self {
        EffectMap::default()
    }

    /// Where `name` is, or would be inserted, in the order of the names.
    fn slot(&self, name: EffectName) -> Result<usize, usize> {
        self.0.binary_search_by(|(k, _)| k.as_str().cmp(name.as_str()))
    }

    /// Sets the value of `name`; the value it had, if any.
    pub fn insert(&mut self, name: EffectName, value: V) -> Option<V> {
        match self.slot(name) {
            Ok(i) => Some(std::mem::replace(&mut self.0[i].1, value)),
            Err(i) => {
                self.0.insert(i, (name, value));
                None
            }
        }
    }

    /// The value of `name`, if any.
    pub fn get(&self, name: EffectName) -> Option<&V> {
        self.slot(name).ok().map(|i| &self.0[i].1)
    }

    /// The value of `name` to change, if any.
    pub fn get_mut(&mut self, name: EffectName) -> Option<&mut V> {
        self.slot(name).ok().map(|i| &mut self.0[i].1)
    }

    /// True without entries.
    pub fn is_empty(&self) -> bool {
        self.0.is_empty()
    }

    /// Number of entries.
    pub fn len(&self) -> usize {
        self.0.len()
    }

    /// The entries in the order of the names.
    pub fn iter(&self) -> impl Iterator<Item = (EffectName, &V)> {
        self.0.iter().map(|(k, v)| (*k, v))
    }

    /// The entries to change, in the order of the names.
    pub fn iter_mut(&mut self) -> impl Iterator<Item = (EffectName, &mut V)> {
        self.0.iter_mut().map(|(k, v)| (*k, v))
    }
}

impl<V> FromIterator<(EffectName, V)> for EffectMap<V> {
    /// Later entries of one name replace earlier ones (as a `BTreeMap`'s do).
    fn from_iter<I: IntoIterator<Item = (EffectName, V)>>(entries: I) -> Self {
        let mut m = EffectMap::new();
        for (k, v) in entries {
            m.insert(k, v);
        }
        m
    }
}

impl<'a, V> IntoIterator for &'a EffectMap<V> {
    type Item = (EffectName, &'a V);
    type IntoIter =
        std::iter::Map<std::slice::Iter<'a, (EffectName, V)>, fn(&'a (EffectName, V)) -> (EffectName, &'a V)>;
    fn into_iter(self) -> Self::IntoIter {
        self.0.iter().map(|(k, v)| (*k, v))
    }
}

/// The value of `name`; panics without one (as a `BTreeMap`'s index does).
impl<V> std::ops::Index<EffectName> for EffectMap<V> {
    type Output = V;
    fn index(&self, name: EffectName) -> &V {
        self.get(name).unwrap_or_else(|| panic!("no entry for `{name}`"))
    }
}

impl<V: Serialize> Serialize for EffectMap<V> {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        s.collect_map(self.0.iter().map(|(k, v)| (k.as_str(), v)))
    }
}

impl<'de, V: Deserialize<'de>> Deserialize<'de> for EffectMap<V> {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        Ok(BTreeMap::<EffectName, V>::deserialize(d)?.into_iter().collect())
    }
}

/// Relative change of the loop gain kv below which a closed loop's fit is not repeated with the
/// new kv in [`close_loop`] (see the fit loop: 1e-5 leaves ≈ 0.04 nm of a 4 µm coupling).
pub(crate) const LOOP_KV_HOLD: f64 = 1e-5;

/// Most refits of a closed loop's model with the loop gain kv and transmission gain g its
/// previous fit found.
pub(crate) const LOOP_KV_REFITS: usize = 6;

/// The refits of a closed loop are a fixed-point iteration kv ← kv_fit(kv): a step |ln(kv_fit/kv)|
/// above ln(1 + LOOP_KV_FAR) that is no shorter than the step before stops them (the iteration
/// does not contract: a model that lacks what moves the following error, such as lost motion at
/// reversals, has no kv to settle on), and the fit with the lowest BIC (σ unknown) of those tried
/// is kept. Generator draw 2022 (a 15.4 µm backlash hidden, closed loop, 19 910 samples): kv went
/// 30 → 2.40 → 500 (the grid's end) → 2.54 → 500 … until LOOP_KV_REFITS ran out, six refits for
/// the fit the first two hold.
fn loop_kv_diverges(step: f64, last_step: f64) -> bool {
    step > LOOP_KV_FAR.ln_1p() && step >= last_step
}

/// Relative change of the loop gain kv above which a refit of a closed loop holds the
/// transmission gain g: g's Gauss–Newton step ([`loop_gain_step`]) is taken with the coupling at
/// the stack's kv, and at a kv this far from the fit's it fits the coupling's error instead
/// (generator draw 2046: from the model's start of 30/s to the fitted 47.06/s, the step went to
/// the range's end, 0.8, and three more refits brought g back to 1.012).
pub(crate) const LOOP_KV_FAR: f64 = 0.01;

/// Change of a closed loop's transmission gain g ([`Stack::loop_gain`]) below which the fit is not
/// repeated: 10⁻³ of the lag L_kv[T] − T of a 1 µm lead is 1 nm, under an encoder's noise.
pub(crate) const LOOP_GAIN_HOLD: f64 = 1e-3;

/// Range of a closed loop's transmission gain g: 1 for a continuous loop, 1 + kv·h/2 for a loop
/// sampled every h, more with a computation delay; a stable sampled P loop has kv·h < 1 (g < 1.6).
pub(crate) const LOOP_GAIN_RANGE: (f64, f64) = (0.8, 2.0);

/// Everything a compare computes, for diagnose to build on.
pub(crate) struct Fitted<'a> {
    pub(crate) st: Stack<'a>,
    pub(crate) fs: FitState,
    pub(crate) sig: Vec<f64>,
    pub(crate) est: Vec<bool>,
    pub(crate) notes: Vec<String>,
    /// The stated σ checked against the repeats (None without repeats).
    pub(crate) sigma: Option<SigmaCheck>,
}

pub(crate) fn fit_all<'a>(model: &Model, chans: &'a [Channel], data: &Path) -> Result<Fitted<'a>, VmtError> {
    let mut st = Stack::with_model(chans, model);
    let bad = |m: String| VmtError::bad(data, "", m);
    let mut notes = Vec::new();
    // Every fitted effect must be seen by some channel; a periodic one whose periods these
    // positions cannot resolve is held at zero with a note (its aliases would fit per-target misfit).
    for me in model.effects.iter().filter(|m| m.fit && m.effect.axis == model.axis && predicts(m.effect.name)) {
        if me.effect.name.is_error_motion() {
            check_basis(&st, me).map_err(|f| {
                VmtError::bad(&model.source, format!("effects.{}.{}", me.effect.name, f.key.as_str()), f.message)
            })?;
        }
        let sh = shape(&st, me.effect.name, 1, me.order.unwrap_or(DEFAULT_ORDER), lacks_coulomb(model));
        let period = me.given.iter().any(|g| g == "period").then(|| me.effect.params.get("period")).flatten();
        if !visible(&st, me.effect.name, &sh, period) && sh.hypers.first() == Some(&Hyper::Period) && st.n > 0 {
            notes.push(format!("{} (held at zero in this fit)", unresolved_period_note(&st, me.effect.name)));
        } else if !visible(&st, me.effect.name, &sh, period) {
            return Err(bad(format!(
                "the model fits `{}` on axis {}, but no channel of the data sees it: {}",
                me.effect.name,
                me.effect.axis,
                needs(me.effect.name)
            )));
        }
    }
    // Pass 1: weights from the known σ (1 where unknown); estimate the unknown σ from the residual.
    let mut sig: Vec<f64> = chans.iter().map(|c| c.sigma.unwrap_or(f64::NAN)).collect();
    let est: Vec<bool> = sig.iter().map(|s| s.is_nan()).collect();
    // A fitted resonance over fitted translations (accelerometers) is driven by the guideway a
    // first fit without it shows (`fitted_excitation`); the model is then refitted with those inputs.
    // A given resonance (fit = false) is driven the same way, its frequency and damping held (no joint refit).
    let resonance =
        model.effects.iter().find(|m| m.effect.axis == model.axis && m.effect.name == EffectName::Resonance);
    let mode_over_shapes = chans.iter().any(|c| c.is_accel())
        && resonance.is_some()
        && model.effects.iter().any(|m| m.fit && m.effect.name.is_error_motion());
    let mode_fitted = resonance.is_some_and(|m| m.fit);
    for me in model.effects.iter().filter(|m| !m.fit && m.effect.axis == model.axis) {
        match me.effect.name {
            EffectName::Resonance => notes.push(
                "`resonance` is given (fit = false): its frequency and damping are held at the model's values; the \
                 mode shape at each sensor, its free vibration and its narrow-band amplitudes are linear parameters a \
                 model does not state, so they are fitted"
                    .into(),
            ),
            EffectName::GravityTilt => notes.push(
                "`gravity_tilt` is given (fit = false) but has no parameter a model states: each accelerometer's \
                 tilt polynomial is fitted as with fit = true"
                    .into(),
            ),
            // Given values the fit holds as they are: nothing to say.
            vmt_sim::error_motions!()
            | EffectName::SquarenessXy
            | EffectName::SquarenessXz
            | EffectName::SquarenessYz
            | EffectName::Backlash
            | EffectName::CyclicLead
            | EffectName::ScaleError
            | EffectName::ThermalExpansion
            | EffectName::ThermalDrift
            | EffectName::InterpolationError
            | EffectName::Coulomb
            | EffectName::Viscous
            | EffectName::Stribeck
            | EffectName::Lugre
            | EffectName::ServoLag
            | EffectName::AccelBiasDrift => {}
        }
    }
    let mut bare = model.clone();
    if mode_over_shapes {
        bare.effects.retain(|m| m.effect.name != EffectName::Resonance);
    }
    for pass in 0..2 {
        let per = st_sigma(&st, &sig);
        let w: Vec<f64> = per.iter().map(|s| 1.0 / s).collect();
        let sigma = Sigma::PerSample(per);
        let mut fs = fit_model_on(&st, &bare, &sigma, &w).map_err(|m| bad(format!("fitting the model: {m}")))?;
        // A closed loop carries the transmission through the loop gain the fit finds
        // ([`close_loop`]): refit with it until it holds to LOOP_KV_HOLD (the coupling −L_kv[T]
        // moves by ≈ (δkv/kv)·v·T'/kv: a 2 µm lead of 14 mm at 0.1 m/s and kv 25/s has
        // v·T'/kv ≈ 4 µm, so 0.1 % left 4 nm, the noise of a linear scale, and the shapes
        // absorbed it; kv is fixed far better than that by the lag v/kv of the passes).
        // A sampled loop passes the transmission with the gain g of [`Stack::loop_gain`]: one
        // Gauss–Newton step per refit, held once it moves less than LOOP_GAIN_HOLD.
        // A fitted interpolation error is read at the table's position (`table_position`), which
        // the fitted error itself sets: refit until the shift it gives moves less than
        // INTERP_SHIFT_HOLD·σ on every sample (the first refit leaves an error of the order
        // (2πA/p)²·A/8 in the shift: one or two refits).
        //
        // A kv that does not settle (`loop_kv_diverges`) stops the refits; the fit with the lowest
        // BIC of those tried is kept (`best`, with its BIC), and a note says so.
        let mut best: Option<(Stack, FitState, f64)> = None;
        let mut last_step = f64::INFINITY;
        let mut unsettled = None;
        for _ in 0..LOOP_KV_REFITS {
            let closed = has_closed_loop(chans);
            let kv = fs.terms.iter().find(|t| t.name == EffectName::ServoLag).and_then(|t| t.hyper.first().copied());
            let kv_moved = kv.filter(|kv| closed && *kv > 0.0 && (kv / st.loop_kv - 1.0).abs() > LOOP_KV_HOLD);
            if let Some(kv) = kv_moved {
                let step = (kv / st.loop_kv).ln().abs();
                if loop_kv_diverges(step, last_step) {
                    unsettled = Some((st.loop_kv, kv));
                    break;
                }
                last_step = step;
            }
            // g's step is taken at the stack's kv: far from the fit's, it measures the coupling's
            // kv error, not g (LOOP_KV_FAR).
            let far = kv.is_some_and(|kv| closed && (kv / st.loop_kv - 1.0).abs() > LOOP_KV_FAR);
            let g_moved = (!far)
                .then(|| loop_gain_step(&st, &bare, &fs, &sigma, &w))
                .flatten()
                // clamp: LOOP_GAIN_RANGE is the constant (0.8, 2.0), ordered.
                .map(|d| (st.loop_gain + d).clamp(LOOP_GAIN_RANGE.0, LOOP_GAIN_RANGE.1))
                .filter(|g| (g - st.loop_gain).abs() > LOOP_GAIN_HOLD);
            let shift_moved = fitted_interpolation(&fs).map(|ie| interpolation_shift(&st, &ie)).filter(|sh| {
                let before = |k: usize| st.interp_shift.get(k).copied().unwrap_or(0.0);
                sh.iter().zip(&w).enumerate().any(|(k, (s, w))| (s - before(k)).abs() * w > INTERP_SHIFT_HOLD)
            });
            // The servo's period, where the interpolation error's alias fixes it: chosen with the
            // first fit that shows the alias (the refits that follow settle kv, g and the shift
            // with it), checked again once the rest holds.
            let held = kv_moved.is_none() && g_moved.is_none() && shift_moved.is_none();
            let servo_moved =
                (held || st.servo_period.is_nan()).then(|| choose_servo_period(&st, &fs, &sigma, &w)).flatten();
            if kv_moved.is_none() && g_moved.is_none() && shift_moved.is_none() && servo_moved.is_none() {
                break;
            }
            let mut next = st.with_loop(kv_moved.unwrap_or(st.loop_kv), g_moved.unwrap_or(st.loop_gain));
            if let Some(sh) = shift_moved {
                next = next.with_interpolation_shift(sh);
            }
            if let Some(h) = servo_moved {
                next = next.with_servo_period(h);
            }
            let refit =
                refit_model_on(&next, &bare, &sigma, &w, &fs).map_err(|m| bad(format!("fitting the model: {m}")))?;
            let bic = fs.bic_unknown_sigma(&w, st.n);
            let tried = (std::mem::replace(&mut st, next), std::mem::replace(&mut fs, refit), bic);
            if best.as_ref().is_none_or(|b| bic < b.2) {
                best = Some(tried);
            }
        }
        if let Some((held, fitted)) = unsettled {
            if let Some((b_st, b_fs, bic)) = best {
                if bic < fs.bic_unknown_sigma(&w, st.n) {
                    (st, fs) = (b_st, b_fs);
                }
            }
            if pass == 1 || !est.iter().any(|e| *e) {
                notes.push(format!(
                    "closed loop: the loop gain kv did not settle: the fit with the loop at kv = {:.4} 1/s found {:.4} 1/s, \
                     further from it than the step before; the refits stopped and the fit with the lowest BIC \
                     (σ unknown) of those tried is kept (kv = {:.4} 1/s in the loop). An effect the model lacks moves \
                     the following error: lost motion at reversals (`backlash`) and a lag the loop does not explain \
                     do this",
                    held,
                    fitted,
                    st.loop_kv
                ));
            }
        }
        if pass == 0 && est.iter().any(|e| *e) {
            let mut k0 = 0;
            for (j, c) in chans.iter().enumerate() {
                let r = &fs.residual[k0..k0 + c.y.len()];
                k0 += c.y.len();
                if est[j] {
                    let (s, how) = match repeatability_sigma(c, r) {
                        Some(s) => (s, "pooled spread of repeated readings at each target and direction"),
                        None => (
                            estimate_noise_sigma(r).map_err(|e| {
                                bad(format!(
                                    "sensor `{}` in run `{}` has no sigma in the manifest and its {} readings are \
                                     too few to estimate it ({e}); give `sigma` for the sensor",
                                    c.sensor,
                                    c.run,
                                    c.y.len()
                                ))
                            })?,
                            "successive differences of the residual",
                        ),
                    };
                    sig[j] = s;
                    notes.push(format!(
                        "sigma of `{}` in run `{}` estimated from the data ({how}): {} {}",
                        c.sensor,
                        c.run,
                        fmt_num(s),
                        channel_unit(c)
                    ));
                }
            }
            continue;
        }
        if has_closed_loop(chans) && st.servo_period > 0.0 {
            notes.push(format!(
                "closed loop: the servo samples the scale every {:.4} ms (a whole number of ticks in every log interval; \
                 chosen by the fit of the interpolation error's response through the sampled loop, which at speed \
                 reaches the motor at its alias)",
                st.servo_period * 1e3
            ));
        }
        if has_closed_loop(chans) && st.loop_kv.is_finite() {
            let g = st.loop_gain;
            notes.push(format!(
                "closed loop: the transmission reaches the following channel through the loop (kv = {:.4} 1/s) with \
                 gain g = {g:.4} on its lag (1 for a continuous loop; a loop sampled every h gives g ≈ 1 + kv·h/2{})",
                st.loop_kv,
                if g > 1.0 { format!(": h ≈ {:.3} ms", 2.0 * (g - 1.0) / st.loop_kv * 1e3) } else { String::new() }
            ));
        }
        let (st, fs) = if mode_over_shapes {
            let st2 = match fitted_excitation(&st, &fs) {
                Some(ex) => st.with_excitation(ex),
                None => st.with_excitation(st.excitation.clone()),
            };
            // The mode refitted jointly with the shapes that drive it (`refit_coupled`) from the fit
            // with it (`fs2`); a given mode keeps its frequency and damping.
            //
            // A fitted mode whose model states (f, ζ) (a diagnosis's joint optimum, written by
            // `add`) is refitted from there too ([`ModeStart::Stated`]): the model fitted with the
            // mode held at the stated values, its gains and the shapes around it fitted as a given
            // mode's are, then (f, ζ) freed. The scan starts from shapes that absorbed the mode's
            // response and can end at another optimum: on the mode + roll pair's generator draw
            // 1012 (38.04 Hz, ζ 0.0144, with the roll in the model) it ended at 39.14 Hz,
            // normalised RMS 11.2, even from the true (f, ζ), where this start from the
            // diagnosis's 38.74 Hz ends at 38.04 Hz, normalised RMS 0.97. The two starts run side
            // by side (rayon); the lower weighted residual wins.
            let states_mode = resonance.is_some_and(|m| {
                m.fit && ["frequency", "damping"].iter().all(|k| m.effect.params.get(k).is_some_and(|v| v.is_finite()))
            });
            let (scanned, second) = rayon::join(
                || {
                    let fs2 = fit_model_on(&st2, model, &sigma, &w)?;
                    let start = if mode_fitted { ModeStart::Scan } else { ModeStart::Held };
                    let first = refit_coupled(&st, &st2, &fs2, &sigma, &w, start, &quiet);
                    Ok::<_, ModelCheckError>((fs2, first))
                },
                || {
                    if !states_mode {
                        return None;
                    }
                    let mut held = model.clone();
                    held.effects
                        .iter_mut()
                        .filter(|m| m.effect.name == EffectName::Resonance)
                        .for_each(|m| m.fit = false);
                    let fs_held = fit_model_on(&st2, &held, &sigma, &w).ok()?;
                    refit_coupled(&st, &st2, &fs_held, &sigma, &w, ModeStart::Stated, &quiet)
                },
            );
            let (fs2, first) = scanned.map_err(|m| bad(format!("fitting the model: {m}")))?;
            let rss = |fs: &FitState| weighted_ss(&fs.residual, &w);
            match (first, second) {
                (Some(a), Some(b)) if rss(&b.1) < rss(&a.1) => (b.0, b.1),
                (Some(a), _) => (a.0, a.1),
                (None, Some(b)) if rss(&b.1) < rss(&fs2) => (b.0, b.1),
                (None, _) => (st2, fs2),
            }
        } else {
            (st, fs)
        };
        let sigma = sigma_check(chans, &fs.residual, &est);
        if let Some((sc, k)) = sigma.as_ref().and_then(|sc| Some((sc, sc.scale?))) {
            notes.push(format!(
                "the manifest's sigma ({} m) is inconsistent with the repeated readings ({} m from {} degrees of \
                 freedom, χ² test p = {:.2e}): the significance uses the stated sigma × {k:.3} (the repeats' \
                 upper 95 % bound)",
                fmt_num(sc.stated.unwrap_or(f64::NAN)),
                fmt_num(sc.from_repeats),
                sc.dof,
                sc.p_value.unwrap_or(f64::NAN)
            ));
        }
        return Ok(Fitted { st, fs, sig, est, notes, sigma });
    }
    Err(VmtError::Internal("fit loop ended".into()))
}

/// A fitted interpolation error's shift ([`Stack::interp_shift`]) is held once a refit moves it
/// less than this many σ of its channel on every sample ([`fit_all`]'s loop).
pub const INTERP_SHIFT_HOLD: f64 = 0.05;

/// The interpolation error a fit holds (its period and the amplitude and phase of its sine and
/// cosine coefficients, A·sin(2πx/p + φ) = A·cos φ·sin + A·sin φ·cos), if it has one.
pub(crate) fn fitted_interpolation(fs: &FitState) -> Option<InterpolationError> {
    let ti = fs.terms.iter().position(|t| t.name == EffectName::InterpolationError)?;
    let (c, period) = (term_coefs(fs, ti), *fs.terms[ti].hyper.first()?);
    let [a, b] = [*c.first()?, *c.get(1)?];
    (period > 0.0).then(|| InterpolationError { period, amplitude: a.hypot(b), phase: b.atan2(a) })
}

/// Weighted χ² by which a servo period must lower the fit's residual for [`choose_servo_period`]
/// to take it: about twice 2·ln(the candidates a log allows, 16–32 on the generator's logs), so
/// that the choice among them is not made by the noise.
pub const SERVO_PERIOD_MARGIN: f64 = 10.0;

/// The servo period (s) among [`servo_period_candidates`] at which the fit `fs` on `st` — its
/// design with the fitted interpolation error's columns through the sampled loop
/// ([`wave_lag_sampled`]), every other column as it is — leaves the smallest weighted residual,
/// when that is [`SERVO_PERIOD_MARGIN`] below the fit's own (weights `w` = 1/σ). None without a
/// closed loop, a finite kv or a fitted interpolation error.
pub(crate) fn choose_servo_period(st: &Stack, fs: &FitState, sigma: &Sigma, w: &[f64]) -> Option<f64> {
    if !has_closed_loop(st.chans) || !st.loop_kv.is_finite() {
        return None;
    }
    let ti = fs.terms.iter().position(|t| t.name == EffectName::InterpolationError)?;
    if term_coefs(fs, ti).iter().all(|c| *c == 0.0) {
        return None;
    }
    let start = fs.n_offsets + fs.terms[..ti].iter().map(|t| t.shape.coefs.len()).sum::<usize>();
    let t = &fs.terms[ti];
    let rss_at = |h: f64| {
        let sh = st.with_servo_period(h);
        let mut cols = fs.cols.clone();
        for (k, c) in columns(&sh, t.name, &t.shape, &t.hyper).into_iter().enumerate() {
            cols[start + k] = c;
        }
        solve_blocks(&sh, &fs.target, &cols, sigma).map_or(f64::INFINITY, |(_, r)| weighted_ss(&r, w))
    };
    let candidates = servo_period_candidates(st);
    let rss: Vec<f64> = candidates.par_iter().map(|&h| rss_at(h)).collect();
    let own = weighted_ss(&fs.residual, w);
    // The lowest in candidate order (the same on any number of threads).
    rss.iter()
        .zip(&candidates)
        .fold((own - SERVO_PERIOD_MARGIN, None), |b, (r, h)| if *r < b.0 { (*r, Some(*h)) } else { b })
        .1
}

/// Minimum degrees of freedom of the repeatability estimate of σ (relative error ≈ 1/√(2·dof) ≤ 22 %).
pub(crate) const MIN_REPEAT_DOF: usize = 10;

/// Within-group scatter of repeated readings (ISO 230-2 repeatability): the residual grouped by
/// (target, direction), returns (SS = Σ (r − r̄_group)², dof = N − G); None when no reading is
/// repeated.
pub(crate) fn repeat_scatter(c: &Channel, r: &[f64]) -> Option<(f64, usize)> {
    let key = |i: usize| (c.x[i].to_bits(), if c.d[i] > 0.0 { 1i8 } else { -1 });
    vmt_estimators::modelcheck::pooled_group_scatter((0..r.len()).map(|i| (key(i), r[i])))
}

/// σ of one reading from repeated approaches: σ̂² = SS/(N − G) ([`repeat_scatter`]); None with
/// fewer than [`MIN_REPEAT_DOF`] degrees of freedom or a zero spread.
pub(crate) fn repeatability_sigma(c: &Channel, r: &[f64]) -> Option<f64> {
    let (ss, dof) = repeat_scatter(c, r).filter(|(_, d)| *d >= MIN_REPEAT_DOF)?;
    let s = (ss / dof as f64).sqrt();
    (s > 0.0).then_some(s)
}

/// Two-sided p-value below which a stated σ is inconsistent with the repeats ([`sigma_check`]).
pub(crate) const SIGMA_TEST_LEVEL: f64 = 0.01;

/// What σ the significance (ΔBIC) of `diagnose` uses (FORMAT.md §4 optional `sigma.used`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum SigmaUse {
    /// The manifest's σ, consistent with the repeats (or no repeats to check it): χ² form of ΔBIC.
    Stated,
    /// The manifest gives no σ: estimated from the repeats (or the residual) and used as known.
    Estimated,
    /// The manifest's σ is inconsistent with the repeats: the stated σ of every checked channel is
    /// scaled by [`SigmaCheck::scale`], to the upper 95 % confidence bound of the repeats' scatter.
    FromRepeats,
}

/// The noise σ of the point-table channels checked against their repeated readings (FORMAT.md §4
/// optional `sigma`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SigmaCheck {
    /// The manifest's σ of the checked channels, m: √(Σ dof_j·σ_j² / Σ dof_j); None when no checked
    /// channel states one.
    pub stated: Option<f64>,
    /// Pooled within-group standard deviation of the residual over repeated readings (same target,
    /// same direction, several runs), m: √(Σ SS_j / Σ dof_j).
    pub from_repeats: f64,
    /// Its degrees of freedom: readings − (target, direction) groups, summed over the channels.
    pub dof: usize,
    /// Two-sided p-value of T = Σ SS_j/σ_j² against χ²(dof) (the stated σ is right when T is a
    /// χ²(dof) draw): 2·min(P(χ² ≥ T), P(χ² ≤ T)); None without a stated σ.
    pub p_value: Option<f64>,
    /// What σ the significance uses.
    pub used: SigmaUse,
    /// With `used` = `from_repeats`: the factor applied to the stated σ, √(T / χ²_{dof, 0.95}) (T
    /// of `p_value`, χ²_{dof, 0.95} its lower 5 % point): the upper 95 % confidence bound of σ from
    /// the repeats over the stated σ, so that a σ estimated from few repeats is not understated.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub scale: Option<f64>,
}

/// Checks the stated σ of the point-table (length) channels against their repeated readings in
/// the residual `r` (all samples, stack order): the χ² test of [`SigmaCheck::p_value`]. Channels
/// without a stated σ count in `from_repeats` but not in the test. None when no channel has
/// repeats ([`MIN_REPEAT_DOF`] degrees of freedom in all).
pub(crate) fn sigma_check(chans: &[Channel], r: &[f64], est: &[bool]) -> Option<SigmaCheck> {
    let (mut ss_all, mut dof_all) = (0.0, 0usize);
    let (mut t, mut dof_s, mut var_s) = (0.0, 0usize, 0.0);
    let mut k0 = 0;
    for (j, c) in chans.iter().enumerate() {
        let rc = &r[k0..k0 + c.y.len()];
        k0 += c.y.len();
        // Laser readings of a point table (an encoder time series has no repeated targets).
        let point_table = c.is_laser() && c.encoder.is_none();
        let Some((ss, dof)) = repeat_scatter(c, rc).filter(|_| point_table) else { continue };
        ss_all += ss;
        dof_all += dof;
        if let Some(s) = c.sigma.filter(|_| !est[j]) {
            t += ss / (s * s);
            dof_s += dof;
            var_s += dof as f64 * s * s;
        }
    }
    if dof_all < MIN_REPEAT_DOF || ss_all <= 0.0 {
        return None;
    }
    let p_value = (dof_s >= MIN_REPEAT_DOF)
        .then(|| vmt_estimators::modelcheck::chi_square_sf(t, dof_s as f64).ok())
        .flatten()
        .map(|upper: f64| (2.0 * upper.min(1.0 - upper)).min(1.0));
    let used = match p_value {
        None if dof_s == 0 && est.iter().any(|e| *e) => SigmaUse::Estimated,
        Some(p) if p < SIGMA_TEST_LEVEL => SigmaUse::FromRepeats,
        None | Some(_) => SigmaUse::Stated,
    };
    let scale = (used == SigmaUse::FromRepeats)
        .then(|| vmt_estimators::modelcheck::chi_square_isf(0.95, dof_s as f64).ok())
        .flatten()
        .map(|q| (t / q).sqrt());
    Some(SigmaCheck {
        stated: (dof_s > 0).then(|| (var_s / dof_s as f64).sqrt()),
        from_repeats: (ss_all / dof_all as f64).sqrt(),
        dof: dof_all,
        p_value,
        used,
        scale,
    })
}

/// The per-sample σ the significance of `diagnose` uses: `per` (the fit's σ), with the stated σ of
/// the checked (point-table laser) channels scaled by [`SigmaCheck::scale`] when the repeats
/// reject it.
pub(crate) fn significance_sigma(f: &Fitted, per: &[f64]) -> Vec<f64> {
    let Some(k) = f.sigma.as_ref().and_then(|sc| sc.scale) else { return per.to_vec() };
    let mut out = Vec::with_capacity(per.len());
    let mut k0 = 0;
    for (j, c) in f.st.chans.iter().enumerate() {
        let m = c.y.len();
        let checked = c.is_laser() && c.encoder.is_none() && !f.est[j];
        out.extend(per[k0..k0 + m].iter().map(|s| if checked { s * k } else { *s }));
        k0 += m;
    }
    out
}

/// Whether a fitted error motion's `basis` and `order` (FORMAT.md §2) can be fitted on these
/// channels: the bases other than `poly` on readings of the motion itself (lasers; not on
/// accelerometers, which see only its second derivative); `table` (one value per target) on a
/// point table (the positions repeat: at most half as many distinct positions as readings); an
/// `order` these m distinct positions can determine after the offsets (Legendre degree ≤ m − 1,
/// B-splines and table values 2..=m, harmonics 1..=(m − 2)/2 beside their slope).
pub(crate) fn check_basis(st: &Stack, me: &ModelEffect) -> Result<(), BasisFault> {
    let name = me.effect.name;
    let seeing: Vec<&Channel> = st.chans.iter().filter(|c| c.s_motion(name) != 0.0).collect();
    let mut xs: Vec<f64> = seeing.iter().flat_map(|c| c.x.iter().copied()).collect();
    xs.sort_by(f64::total_cmp);
    xs.dedup();
    let m = xs.len() as u32;
    let readings: usize = seeing.iter().map(|c| c.y.len()).sum();
    let basis = me.basis.unwrap_or(Basis::Poly);
    let fault = |key, message| Err(BasisFault { key, message });
    if basis != Basis::Poly && seeing.iter().any(|c| c.is_accel()) {
        return fault(
            BasisKey::Basis,
            format!(
                "basis `{}` is fitted to readings of the motion itself; `{name}` is seen here by accelerometers \
             (its second derivative): use `poly` or leave `basis` out",
                basis.as_str()
            ),
        );
    }
    // index: m is a count of distinct positions (a u32 from a length), widened for a comparison only.
    if basis == Basis::Table && 2 * m as usize > readings {
        return fault(
            BasisKey::Basis,
            format!(
                "basis `table` is one value per target of a point table; these data have {m} distinct positions in \
             {readings} readings (a time series, or no repeated targets): use `poly`, `bspline` or `harmonics` \
             with an `order`"
            ),
        );
    }
    let Some(order) = me.order else { return Ok(()) };
    let (lo, hi, what) = match basis {
        Basis::Poly => (1, m.saturating_sub(1), "a Legendre degree"),
        Basis::Bspline => (2, m, "a number of B-splines"),
        Basis::Table => (2, m, "a number of table values"),
        Basis::Harmonics => (1, m.saturating_sub(2) / 2, "a number of harmonics"),
    };
    if order < lo || order > hi {
        return fault(
            BasisKey::Order,
            format!(
                "order {order} for basis `{}`: expected {what} from {lo} to {hi}, what {m} distinct positions \
             determine after the per-run offsets",
                basis.as_str()
            ),
        );
    }
    Ok(())
}

/// The model key a [`check_basis`] refusal names: `effects.NAME.basis` or `effects.NAME.order`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum BasisKey {
    /// The basis does not suit the channels that see the effect.
    Basis,
    /// The order is outside what the data's distinct positions determine.
    Order,
}

impl BasisKey {
    /// The key's name in the model file.
    pub(crate) fn as_str(self) -> &'static str {
        match self {
            BasisKey::Basis => "basis",
            BasisKey::Order => "order",
        }
    }
}

/// Why [`check_basis`] refuses an effect's basis or order: the key at fault and what is expected.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct BasisFault {
    /// The key at fault.
    pub key: BasisKey,
    /// What is wrong and what is expected, for the user.
    pub message: String,
}

/// Per-sample σ from per-channel σ (NaN → 1: unweighted first pass), with a following channel's
/// command uncertainty added in quadrature (`EncoderRole::Following`'s `command_sigma`).
pub(crate) fn st_sigma(st: &Stack, sig: &[f64]) -> Vec<f64> {
    let mut v = Vec::with_capacity(st.n);
    for (c, s) in st.chans.iter().zip(sig) {
        let s = if s.is_finite() { *s } else { 1.0 };
        match &c.encoder {
            // A following channel of a command read from few decimals: its reading's uncertainty
            // added in quadrature.
            Some(EncoderRole::Following { command_sigma, .. }) if command_sigma.len() == c.y.len() => {
                v.extend(command_sigma.iter().map(|u| s.hypot(*u)));
            }
            Some(EncoderRole::Following { .. } | EncoderRole::Transmission { .. }) | None => {
                v.extend(std::iter::repeat(s).take(c.y.len()))
            }
        }
    }
    v
}

/// True when some channel sees effect `name` (a non-zero column) at the hyper-parameter `fixed`, or
/// at some value of its search grid.
pub(crate) fn visible(st: &Stack, name: EffectName, sh: &Shape, fixed: Option<f64>) -> bool {
    if name == EffectName::Resonance {
        // Any excited channel or any narrow-band segment (sin/cos are never both zero).
        return st.excitation.iter().any(|e| !e.is_empty()) || !resonance_segments(st).is_empty();
    }
    let grid: Vec<f64> = match (fixed, sh.hypers.first()) {
        (Some(v), _) => vec![v],
        // Where these columns are zero does not depend on the value: 1 − exp(−t/τ) is non-zero
        // for every τ at t > 0 (tau); a following channel's start column e^{−kv·(t − t₀)} is 1 at
        // t₀ for every kv (kv). So one grid value answers for the grid. (A period's columns are
        // zeroed where the positions do not resolve it, a Stribeck weight exp(−|v/vs|^δ) can
        // underflow at one vs and not another: their grids are scanned.)
        (None, Some(&h)) if matches!(h, Hyper::Tau | Hyper::Kv) => {
            hyper_grid(st, name, h).0.into_iter().take(1).collect()
        }
        (None, Some(&h)) => hyper_grid(st, name, h).0,
        (None, None) => vec![1.0],
    };
    // A grid is scanned only when some channel reads the effect's path at all: a periodic effect
    // through its wave's path, a Stribeck curve through a force reading.
    let read = match (catalogue_row(name).period, name) {
        (Some(r), _) => st.chans.iter().any(|c| r.path.sensitivity(c) != 0.0),
        (None, EffectName::Stribeck) => st.chans.iter().any(|c| c.s_force() != 0.0),
        (None, _) => true,
    };
    read && grid.iter().any(|g| {
        let h: Vec<f64> = sh.hypers.iter().map(|_| *g).collect();
        columns(st, name, sh, &h).iter().any(|c| c.iter().any(|v| *v != 0.0))
    })
}

/// What data shows an effect (for the "missing channel" message and the advice; [`catalogue_row`]).
pub(crate) fn needs(name: EffectName) -> &'static str {
    catalogue_row(name).needs
}

/// The SI unit of a channel's readings and residual: N (motor force), m/s² (accelerometer), rad
/// (an angular laser's deviations: pitch, yaw, roll), else m.
fn channel_unit(c: &Channel) -> &'static str {
    match c.kind {
        SensorKind::MotorForce => "N",
        SensorKind::Accelerometer => "m/s²",
        SensorKind::LaserAngular => "rad",
        SensorKind::Command
        | SensorKind::EncoderRotary
        | SensorKind::EncoderLinear
        | SensorKind::LaserLinear
        | SensorKind::LaserStraightness
        | SensorKind::LaserVector
        | SensorKind::Velocity
        | SensorKind::Temperature
        | SensorKind::Pressure
        | SensorKind::Humidity => "m",
    }
}

pub(crate) fn load_channels(
    model: &Model,
    set: &MeasurementSet,
    data: &Path,
) -> Result<(Vec<Channel>, Vec<String>), VmtError> {
    let (chans, mut notes) = channels(set, model.axis);
    if chans.is_empty() {
        return Err(VmtError::bad(
            data,
            "runs",
            format!(
                "no channel the model can be compared with: expected a positioning point table of axis {} with a \
                 laser or encoder deviation column, or a constant-velocity or friction-sweep time series with a \
                 `feed` and a motor_force or accelerometer column",
                model.axis
            ),
        ));
    }
    for me in model.effects.iter().filter(|m| !predicts(m.effect.name)) {
        notes.push(format!("effect `{}` is not predicted (module doc): left out", me.effect.name));
    }
    // The comparison runs along the model's axis; an effect of another axis is never silently dropped.
    for me in model.effects.iter().filter(|m| m.effect.axis != model.axis) {
        notes.push(format!(
            "effect `{}` on axis {} is left out: this comparison is along axis {} (the model's `axis`), and the data's \
             channels of that axis are the ones compared",
            me.effect.name, me.effect.axis, model.axis
        ));
    }
    Ok((chans, notes))
}

/// `vmt compare` on in-memory inputs: fits the model's free parameters to the point-table channels
/// of `set` and reports residual statistics per channel and overall (module doc for the model;
/// FORMAT.md §4 for the keys). `data` names the data in messages and the report.
pub fn compare(model: &Model, set: &MeasurementSet, data: &Path) -> Result<CompareReport, VmtError> {
    let (chans, mut notes) = load_channels(model, set, data)?;
    let f = fit_all(model, &chans, data)?;
    notes.extend(f.notes.iter().cloned());
    let pred_total: Vec<f64> = f.st.y().iter().zip(&f.fs.residual).map(|(y, r)| y - r).collect();
    // Each sample's σ: its channel's, with a command's reading uncertainty where it has one.
    let per = st_sigma(&f.st, &f.sig);
    let mut out = Vec::new();
    let mut k0 = 0;
    let mut sum_sq = 0.0;
    for (j, c) in chans.iter().enumerate() {
        let m = c.y.len();
        let r = &f.fs.residual[k0..k0 + m];
        let p = &pred_total[k0..k0 + m];
        let per_c = &per[k0..k0 + m];
        k0 += m;
        sum_sq += r.iter().zip(per_c).map(|(v, s)| (v / s).powi(2)).sum::<f64>();
        out.push(channel_report(c, r, p, (f.sig[j], per_c), f.est[j], f.fs.coefs[f.st.group[j]]));
    }
    let n = f.st.n;
    let at_bound = fit_at_bound(&f.fs);
    for (e, names) in &at_bound {
        notes.push(format!("fitted `{e}`: {}", bound_note(names)));
    }
    Ok(CompareReport {
        model: model.source.display().to_string(),
        data: data.display().to_string(),
        channels: out,
        normalized_rms: (sum_sq / n as f64).sqrt(),
        fitted: term_params(&f.fs, model),
        n,
        n_params: f.fs.cols.len(),
        notes,
        history: read_history(&history_path(&model.source)).unwrap_or_default(),
        shapes: shape_reports(&f.fs),
        sigma: f.sigma,
        at_bound,
    })
}

/// One channel's residual statistics (FORMAT.md §4): `s` its σ, `per` each sample's ([`st_sigma`]).
pub(crate) fn channel_report(
    c: &Channel,
    r: &[f64],
    p: &[f64],
    (s, per): (f64, &[f64]),
    est: bool,
    offset: f64,
) -> ChannelReport {
    let m = r.len();
    let rms = (r.iter().map(|v| v * v).sum::<f64>() / m as f64).sqrt();
    let normalized_rms = (r.iter().zip(per).map(|(v, s)| (v / s).powi(2)).sum::<f64>() / m as f64).sqrt();
    let lag = (m / 4).clamp(1, 20);
    let acf = autocorrelation(r, lag).ok().map(|a| a.fraction_outside);
    let lb = ljung_box(r, lag, 0).ok().map(|l| l.p_value);
    let labels: Vec<i8> = c.d.iter().map(|d| if *d > 0.0 { 1 } else { -1 }).collect();
    let by_direction =
        bin_by_label(r, &labels).map(|b| b.into_iter().map(|x| (x.key, x.mean, x.rms)).collect()).unwrap_or_default();
    let by_cycle =
        bin_by_label(r, &c.cycle).map(|b| b.into_iter().map(|x| (x.key, x.mean, x.rms)).collect()).unwrap_or_default();
    let ranged = |keys: &[f64]| -> Vec<(f64, f64, f64, f64)> {
        let lo = keys.iter().copied().fold(f64::INFINITY, f64::min);
        let hi = keys.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        if hi <= lo {
            return Vec::new();
        }
        let edges = match uniform_edges(lo, hi + 1e-12 * (hi - lo).abs().max(1.0), 5) {
            Ok(e) => e,
            Err(_) => return Vec::new(),
        };
        bin_by_edges(r, keys, &edges)
            .map(|b| {
                b.bins
                    .into_iter()
                    .filter_map(|x| Some((x.lower, x.upper, x.mean?, x.rms?)))
                    .collect::<Vec<(f64, f64, f64, f64)>>()
            })
            .unwrap_or_default()
    };
    let periodogram =
        |x: &[f64]| frequency_grid(x, 5.0, None).ok().and_then(|g| ls_periodogram(x, r, &Sigma::Unknown, &g).ok());
    let spatial = periodogram(&c.x);
    let spectrum_peaks = spatial
        .as_ref()
        .map(|pg| {
            let mut idx: Vec<usize> = (0..pg.frequency.len()).collect();
            idx.sort_by(|a, b| pg.amplitude[*b].total_cmp(&pg.amplitude[*a]));
            idx.into_iter().take(3).map(|i| (1.0 / pg.frequency[i], pg.amplitude[i])).collect()
        })
        .unwrap_or_default();
    let spectrum = match c.kind {
        SensorKind::Accelerometer => periodogram(&c.t),
        SensorKind::Command
        | SensorKind::EncoderRotary
        | SensorKind::EncoderLinear
        | SensorKind::LaserLinear
        | SensorKind::LaserStraightness
        | SensorKind::LaserAngular
        | SensorKind::LaserVector
        | SensorKind::MotorForce
        | SensorKind::Velocity
        | SensorKind::Temperature
        | SensorKind::Pressure
        | SensorKind::Humidity => spatial,
    }
    .map(|pg| pg.frequency.into_iter().zip(pg.amplitude).collect())
    .unwrap_or_default();
    ChannelReport {
        run: c.run.clone(),
        unit: channel_unit(c).into(),
        sensor: c.sensor.clone(),
        rms,
        normalized_rms,
        fit_percent: fit_percent(&c.y, p).unwrap_or(f64::NAN),
        sigma: s,
        sigma_estimated: est,
        offset,
        acf_fraction_outside: acf,
        ljung_box_p: lb,
        by_direction,
        by_cycle,
        by_position: ranged(&c.x),
        by_time: ranged(&c.t),
        spectrum_peaks,
        spectrum,
    }
}

/// The candidates for effects the model lacks that phase 1 can express, each with its shape.
pub(crate) fn candidate_names(model: &Model, st: &Stack) -> Vec<EffectName> {
    EffectName::ALL
        .iter()
        .copied()
        .filter(|n| predicts(*n) && model.get(*n, model.axis).is_none())
        .filter(|n| visible(st, *n, &candidate_shape(st, *n, lacks_coulomb(model)), None))
        .collect()
}

/// A candidate's shape: error motions as a cubic without constant term; the positioning candidate
/// without its linear term as well (a linear positioning error is the scale error's signature).
pub(crate) fn candidate_shape(st: &Stack, n: EffectName, with_fc: bool) -> Shape {
    shape(st, n, if n == EffectName::Positioning { 2 } else { 1 }, DEFAULT_ORDER, with_fc)
}

/// True when the model has no `coulomb` effect on its axis (a Stribeck term then fits its own Fc).
pub(crate) fn lacks_coulomb(model: &Model) -> bool {
    model.get(EffectName::Coulomb, model.axis).is_none()
}

/// The model's Coulomb level: fitted (`fitted`) or known, 0 without one, N.
pub(crate) fn coulomb_level(model: &Model, fitted: &EffectMap<BTreeMap<String, f64>>) -> f64 {
    fitted
        .get(EffectName::Coulomb)
        .and_then(|m| m.get("fc").copied())
        .or_else(|| model.get(EffectName::Coulomb, model.axis).and_then(|m| m.effect.params.get("fc")))
        .unwrap_or(0.0)
}

/// Grid points of a screened resonance search evaluated exactly (of ≈ 200 frequencies × 6 dampings).
pub(crate) const RESONANCE_SCREEN: usize = 12;

/// A stage of [`diagnose_with`], for a progress display: what the diagnosis is doing now.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Stage {
    /// Fitting the model to the data.
    FittingModel,
    /// Fitting and ranking every candidate effect the model lacks.
    RankingCandidates,
    /// A significant mode refitted jointly with the shapes that drive it: the frequency scan of
    /// `round` (from 1) of `rounds`, each start then refined.
    ModeScan {
        /// This round, from 1.
        round: usize,
        /// The rounds in all.
        rounds: usize,
    },
    /// The joint mode fit: the shapes re-chosen with the mode in the model, after scan `round`.
    ModeShapes {
        /// The scan round they follow, from 1.
        round: usize,
    },
    /// The joint mode fit: refinement and shapes in turn until the frequency holds, round `round`
    /// (from 1) of at most `most`.
    ModePolish {
        /// This round, from 1.
        round: usize,
        /// The rounds at most.
        most: usize,
    },
}

impl std::fmt::Display for Stage {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Stage::FittingModel => write!(f, "fitting the model"),
            Stage::RankingCandidates => write!(f, "ranking the candidates the model lacks"),
            Stage::ModeScan { round, rounds } => write!(f, "mode with its shapes: frequency scan {round} of {rounds}"),
            Stage::ModeShapes { round } => write!(f, "mode with its shapes: shapes re-chosen after scan {round}"),
            Stage::ModePolish { round, most } => {
                write!(f, "mode with its shapes: polishing, round {round} (of at most {most})")
            }
        }
    }
}

/// Where a stage goes when nobody watches ([`diagnose`], `compare`).
pub(crate) fn quiet(_: Stage) {}

/// `vmt diagnose` on in-memory inputs: fits the model, then every catalogue effect the model lacks
/// that these channels can show is fitted to the weighted residual together with the model's own
/// linear columns, ranked by ΔBIC with verdicts (`vmt_estimators::modelcheck::rank_candidates`).
pub fn diagnose(model: &Model, set: &MeasurementSet, data: &Path) -> Result<DiagnoseReport, VmtError> {
    diagnose_with(model, set, data, &quiet)
}

/// [`diagnose`], telling `progress` each [`Stage`] as it starts (a progress display; the result
/// does not depend on it).
pub fn diagnose_with(
    model: &Model,
    set: &MeasurementSet,
    data: &Path,
    progress: &(dyn Fn(Stage) + Sync),
) -> Result<DiagnoseReport, VmtError> {
    let (chans, mut notes) = load_channels(model, set, data)?;
    progress(Stage::FittingModel);
    let f = fit_all(model, &chans, data)?;
    // From here on, the candidates: built, searched against the fit (a lead against capped
    // shapes too), ranked.
    progress(Stage::RankingCandidates);
    notes.extend(f.notes.iter().cloned());
    let per = st_sigma(&f.st, &f.sig);
    let nrms = (f.fs.residual.iter().zip(&per).map(|(r, s)| (r / s).powi(2)).sum::<f64>() / f.st.n as f64).sqrt();
    let names = candidate_names(model, &f.st);
    // Periodic candidates these positions cannot resolve: not searched, listed with a note.
    let mut unresolved: Vec<EffectName> = Vec::new();
    let mut restricted: Option<String> = None;
    // The periodic effects of the catalogue (a cyclic lead, an interpolation error).
    let periodic = EffectName::ALL.into_iter().filter_map(|n| catalogue_row(n).period.map(|r| (n, r)));
    for (n, range) in periodic {
        if !names.contains(&n) && model.get(n, model.axis).is_none() && !f.st.chans.is_empty() {
            let sh = candidate_shape(&f.st, n, false);
            // Not visible: no period of its range resolvable, or the waves vanish on these positions.
            let sees = |c: &Channel| range.path.sensitivity(c) != 0.0;
            if sh.hypers.first() == Some(&Hyper::Period) && f.st.chans.iter().any(sees) {
                unresolved.push(n);
            }
        } else if names.contains(&n) && n == EffectName::CyclicLead {
            if let Some(p) = shortest_resolvable_period(&f.st).filter(|p| *p > range.lo) {
                restricted = Some(format!(
                    "{n} searched only at periods ≥ {} mm, the shortest these sample positions resolve \
                     (twice the gap between neighbouring targets); a shorter lead needs targets every ≤ P/3 over a period",
                    fmt_num(p * 1e3)
                ));
                notes.extend(restricted.clone());
            }
        }
    }
    let fc_ref = coulomb_level(model, &term_params(&f.fs, model));
    let st = &f.st;
    // A resonance over fitted translations is driven by the guideway the base fit shows.
    let st_mode = fitted_excitation(st, &f.fs).map(|ex| st.with_excitation(ex));
    let w: Vec<f64> = per.iter().map(|s| 1.0 / s).collect();
    // Shape against cyclic lead (fit.rs `LeadCap`): where the model's shapes keep orders whose
    // shortest wavelength 2L/K reaches the lead's searched periods, the lead is ranked against the
    // model refitted with its shapes capped (2L/K > P, so they cannot absorb it), the others
    // against the model as fitted.
    let binding: Vec<(EffectName, LeadCap)> =
        f.fs.shapes
            .iter()
            .filter(|c| !c.given)
            .filter_map(|c| c.lead_cap.filter(|l| !l.in_model && l.free_best > l.order).map(|l| (c.name, l)))
            .collect();
    let split = !binding.is_empty() && names.contains(&EffectName::CyclicLead);
    let fit_sigma = Sigma::PerSample(per.clone());
    // The interpolation error's periods from the residual (`interpolation_periods`), beside the
    // lead's joint scan and the capped fit (rayon): neither needs the other.
    let (interp_scan, lead_fit) = rayon::join(
        || {
            names
                .contains(&EffectName::InterpolationError)
                .then(|| interpolation_periods(st, &f.fs.residual, &w))
                .flatten()
        },
        || -> Result<_, VmtError> {
            // The lead's period and the shapes' orders chosen jointly (`lead_shape_scan`): the
            // orders K* at the best period set the lead's base, and the lead is searched only at
            // periods those orders cannot represent.
            let scan = if split {
                let grid = hyper_grid(st, EffectName::CyclicLead, Hyper::Period).0;
                match (grid.first(), grid.last()) {
                    (Some(lo), Some(hi)) => lead_shape_scan(st, &f.fs, &binding, &w, (*lo, *hi)).map_err(|m| {
                        VmtError::bad(data, "", format!("scanning the cyclic lead against the shapes: {m}"))
                    })?,
                    _ => None,
                }
            } else {
                None
            };
            let joint: Option<Vec<(EffectName, u32)>> = match &scan {
                Some(sc) => Some(sc.orders.clone()),
                // Not nested (B-splines): the shapes capped below the longest period searched.
                None if split => Some(binding.iter().map(|(m, l)| (*m, l.capped_best)).collect()),
                None => None,
            };
            let capped = match &joint {
                Some(orders) => {
                    // Point-table shapes (Legendre, all terms): no sparse selection to carry over.
                    let order_of = |_: usize, me: &ModelEffect| {
                        let n = me.effect.name;
                        let order = orders.iter().find(|(m, _)| *m == n).map(|(_, o)| *o).unwrap_or_else(|| {
                            f.fs.shapes
                                .iter()
                                .find(|c| c.name == n)
                                .map_or(me.order.unwrap_or(DEFAULT_ORDER), |c| c.order)
                        });
                        (order, None)
                    };
                    let fs = fit_model_held(st, model, &fit_sigma, &w, &order_of, &f.fs).map_err(|m| {
                        VmtError::bad(data, "", format!("fitting the model with its shapes capped: {m}"))
                    })?;
                    Some(fs)
                }
                None => None,
            };
            Ok((scan, joint, capped))
        },
    );
    let (scan, joint, capped) = lead_fit?;
    let make = |n: EffectName| -> Candidate {
        {
            let st = match (&st_mode, n == EffectName::Resonance) {
                (Some(sm), true) => sm,
                _ => st,
            };
            let sh = candidate_shape(st, n, lacks_coulomb(model));
            let sh2 = sh.clone();
            let coef: Vec<&str> = sh.coefs.iter().map(|s| s.as_str()).collect();
            let mut c = Candidate::new(n.as_str(), &coef, move |h: &[f64]| {
                let cols = columns(st, n, &sh2, h);
                if cols.iter().all(|c| c.iter().all(|v| *v == 0.0)) {
                    Err(ModelCheckError::VanishingSignature)
                } else {
                    Ok(cols)
                }
            });
            for &h in &sh.hypers {
                let (grid, refine) = hyper_grid(st, n, h);
                c.hyper_parameters.push(HyperParameter { name: h.as_str().to_string(), grid, refine });
            }
            // An interpolation error's period is chosen from the residual (the catalogue's periods
            // miss a real scale's by more than its likelihood peak is wide).
            let c = match &interp_scan {
                Some((periods, independent)) if n == EffectName::InterpolationError => {
                    for h in c.hyper_parameters.iter_mut() {
                        h.grid.clone_from(periods);
                        h.refine = true;
                    }
                    c.chosen_from(*independent)
                }
                Some(_) | None => c,
            };
            let sh3 = sh.clone();
            let mut start = EffectParams::default_for(n);
            if n == EffectName::Stribeck {
                start.set("fc", fc_ref);
            }
            let c = c.with_describe(move |coefs: &[f64], h: &[f64]| describe(n, &sh3, coefs, h, &start));
            // A mode's columns live on a few channels each: the grid search takes them as runs
            // (the same values; open loop only, where the columns are the runs placed in full).
            let c = if n == EffectName::Resonance && !has_closed_loop(st.chans) {
                c.with_sparse(move |h: &[f64]| {
                    let cols = resonance_runs(st, h[0], h[1]);
                    if cols.iter().all(|c| c.runs.iter().all(|(_, v)| v.iter().all(|x| *x == 0.0))) {
                        Err(ModelCheckError::VanishingSignature)
                    } else {
                        Ok(cols)
                    }
                })
            } else {
                c
            };
            // A mode over a large base (flexible shapes): the (f, ζ) grid is screened
            // (`Candidate::with_screen`), the best RESONANCE_SCREEN points evaluated exactly.
            if n == EffectName::Resonance && f.fs.cols.len() > LARGE_DESIGN {
                c.with_screen(RESONANCE_SCREEN)
            } else {
                c
            }
        }
    };
    // Each candidate with its effect (the estimator's candidate knows it by name only).
    let cands: Vec<(EffectName, Candidate)> = names.iter().map(|&n| (n, make(n))).collect();
    let mut ranking: Vec<RankedEffect> = Vec::new();
    let sig_vec = significance_sigma(&f, &per);
    let sigma = Sigma::PerSample(sig_vec.clone());
    let config = DiagnoseConfig::default();
    // The lead is searched at periods shorter than the capped shapes' shortest wavelengths.
    let lead_limit = joint.as_ref().map(|orders| {
        binding
            .iter()
            .zip(orders)
            .map(|((_, l), (_, o))| l.basis.shortest_wavelength(l.span, *o))
            .fold(f64::INFINITY, f64::min)
    });
    // The lead is searched only below the capped shapes' shortest wavelength.
    let limit_lead = |n: EffectName, c: &mut Candidate| {
        if let (Some(lim), EffectName::CyclicLead) = (lead_limit, n) {
            for h in c.hyper_parameters.iter_mut() {
                h.grid.retain(|p| *p < lim);
            }
        }
    };
    let mut cands = cands;
    cands.iter_mut().for_each(|(n, c)| limit_lead(*n, c));
    let split = split && capped.is_some();
    let total = cands.len();
    let (lead_cands, other_cands): (Vec<(EffectName, Candidate)>, Vec<_>) =
        cands.into_iter().partition(|(n, _)| split && *n == EffectName::CyclicLead);
    // Per ranked candidate: its columns at the fitted hyper-parameters, its number of searched
    // hyper-parameters, and whether a better-ranked candidate explained it away.
    let mut fitted: BTreeMap<EffectName, (Vec<Vec<f64>>, usize, bool)> = BTreeMap::new();
    // The free shapes' order curves for the re-choice below (`factored_curves`; not on
    // accelerometer channels) need only the fit: factored beside the ranking (rayon).
    let reshape = !st.chans.iter().any(|c| c.is_accel());
    // Each group ranked against its own fit: the two side by side and beside the curves (rayon),
    // merged in group order (the first error in that order reported).
    let rank_group = |group: Vec<(EffectName, Candidate)>, fs: &FitState| {
        if group.is_empty() {
            return None;
        }
        let group: Vec<Candidate> = group.into_iter().map(|(_, c)| c).collect();
        let base: Vec<Vec<f64>> = fs.cols.iter().filter(|c| c.iter().any(|v| *v != 0.0)).cloned().collect();
        let input =
            vmt_estimators::modelcheck::ResidualInput { residual: &fs.residual, sigma: &sigma, base_columns: &base };
        Some((group.len(), rank_candidates(&input, &group, &config)))
    };
    let lead_fs = capped.as_ref().unwrap_or(&f.fs);
    let ((other, lead), curves) = rayon::join(
        || rayon::join(|| rank_group(other_cands, &f.fs), || rank_group(lead_cands, lead_fs)),
        || match reshape {
            true => factored_curves(st, model, &f.fs, &w, &f.fs.free_orders())
                .map_err(|m| VmtError::bad(data, "", format!("re-choosing the shapes: {m}"))),
            false => Ok(Vec::new()),
        },
    );
    for (len, done) in [other, lead].into_iter().flatten() {
        match done {
            Ok(d) => {
                // Bonferroni over all `total` candidates of this diagnosis, not the group's.
                let scale = total as f64 / len as f64;
                for (r, fit) in d.ranking.into_iter().zip(d.fits) {
                    let mut r = RankedEffect::typed(r).map_err(|e| VmtError::Internal(e.to_string()))?;
                    bonferroni(&mut r, scale, config.family_alpha);
                    // Marginally significant, then explained away by a better-ranked candidate.
                    let away = fit.conditional_delta_bic.is_some() && r.verdict == Verdict::Noise;
                    let k_hyper = fit.k - fit.coefficients.len();
                    fitted.insert(r.effect, (fit.columns, k_hyper, away));
                    ranking.push(r);
                }
            }
            Err(ModelCheckError::NothingToExplain) => {
                notes.push("the model explains the data exactly: nothing to diagnose".into())
            }
            Err(e) => return Err(VmtError::bad(data, "", format!("diagnose: {e}"))),
        }
    }
    let curves = curves?;
    if let (Some(cf), Some(orders)) = (&capped, &joint) {
        if let Some(r) = ranking.iter_mut().find(|r| r.effect == EffectName::CyclicLead) {
            let fit_bic = |fs: &FitState| {
                let k = fs.cols.iter().filter(|c| c.iter().any(|v| *v != 0.0)).count();
                (weighted_ss(&fs.residual, &w), k)
            };
            // The joint scan's BIC change; without one (B-splines), the capped model with the
            // ranked lead: RSS_capped·(1 − explained), k = sine, cosine and the searched period.
            let delta = match &scan {
                Some(sc) => sc.delta_bic,
                None => {
                    let (free, cap) = (fit_bic(&f.fs), fit_bic(cf));
                    let k = 2 + usize::from(r.searched.is_some_and(|m| m > 1));
                    bic_unknown_sigma(cap.0 * (1.0 - r.explained).max(0.0), st.n, cap.1 + k)
                        - bic_unknown_sigma(free.0, st.n, free.1)
                }
            };
            let caps: Vec<(EffectName, LeadCap, u32)> =
                binding.iter().zip(orders).map(|((m, l), (_, o))| (*m, *l, *o)).collect();
            weigh_lead_against_shapes(r, &caps, delta, config.inseparable_margin);
        }
    }
    // A significant mode over fitted shapes: its frequency, damping and gains refitted jointly with
    // the shapes that drive it (`refit_coupled`; the candidate's search held the shapes of the fit
    // without it, which have absorbed part of its response).
    if let (Some(sm), Some(r)) =
        (&st_mode, ranking.iter_mut().find(|r| r.effect == EffectName::Resonance && r.verdict == Verdict::Significant))
    {
        if let Some((c, gains)) = joint_mode(st, sm, &f.fs, &r.params, &fit_sigma, &w, progress) {
            let (fq, dz) = (c.frequency, c.damping);
            let mut note = format!(
                "frequency and damping refitted jointly with the shapes that drive the mode: {} Hz → {} Hz, \
                 damping {} → {}",
                fmt_num(r.params.get("frequency").copied().unwrap_or(f64::NAN)),
                fmt_num(fq),
                fmt_num(r.params.get("damping").copied().unwrap_or(f64::NAN)),
                fmt_num(dz)
            );
            // The joint fit's own limits replace the candidate grid's.
            r.at_bound = [Hyper::Frequency, Hyper::Damping]
                .iter()
                .zip(c.at_bound)
                .filter(|(_, b)| *b)
                .map(|(h, _)| *h)
                .collect();
            if !r.at_bound.is_empty() {
                note += &format!("; {}", bound_note(&r.at_bound));
            }
            r.note = Some(note);
            r.params.insert("frequency".into(), fq);
            r.params.insert("damping".into(), dz);
            r.params.extend(gains);
        }
    }
    // Shapes re-chosen for every candidate model (fit.rs `rechoose_orders`).
    if reshape {
        let ctx = Reshape {
            st,
            model,
            f: &f,
            w: &w,
            sig: &sig_vec,
            fit_sigma: &fit_sigma,
            config: &config,
            total,
            joint: if split { joint.as_deref() } else { None },
            curves: &curves,
        };
        // Each candidate's re-choice is independent of the others': side by side (rayon), the
        // first error in ranking order reported.
        let done: Vec<Result<(), VmtError>> = ranking
            .par_iter_mut()
            .map(|r| {
                let Some((cols, k_hyper, away)) = fitted.get(&r.effect) else { return Ok(()) };
                let name = r.effect;
                let mut c = make(name);
                limit_lead(name, &mut c);
                ctx.apply(r, name, c, cols, *k_hyper, *away).map_err(|m| {
                    VmtError::bad(data, "", format!("re-choosing the shapes with `{name}` in the model: {m}"))
                })
            })
            .collect();
        done.into_iter().collect::<Result<(), VmtError>>()?;
    }
    // Detectable but negligible: say why such an entry is `noise` (with very many samples a tiny
    // misfit passes ΔBIC and the search-corrected p).
    for r in ranking.iter_mut().filter(|r| r.verdict == Verdict::Noise && r.note.is_none()) {
        if r.delta_bic < config.significance_threshold
            && r.p_value.is_some_and(|p| p <= config.family_alpha)
            && r.explained < config.explained_floor
        {
            r.note = Some(format!(
                "detectable (ΔBIC {:.1}, p {:.1e}) but it explains {:.2} % of the residual, below the {:.0} % worth \
                 adding: not significant",
                r.delta_bic,
                r.p_value.unwrap_or(f64::NAN),
                100.0 * r.explained,
                100.0 * config.explained_floor
            ));
        }
    }
    ranking.sort_by(|a, b| a.delta_bic.total_cmp(&b.delta_bic).then_with(|| a.effect.as_str().cmp(b.effect.as_str())));
    // A fitted period at an end of the range searched is a bound, not an estimate: the criterion
    // still improves beyond it, so the signal is not this candidate's in the range searched.
    for r in ranking.iter_mut().filter(|r| r.verdict == Verdict::Significant) {
        if !r.at_bound.contains(&Hyper::Period) {
            continue;
        }
        let p = r.params.get("period").copied().unwrap_or(f64::NAN);
        // The long end: a wave longer than the candidate's periods, what the fitted shapes
        // represent; the short end: a misfit faster than the periods these positions resolve.
        let long = period_range(r.effect).is_some_and(|(lo, hi)| p * p > lo * hi);
        let shapes: Vec<EffectName> = f.fs.shapes.iter().map(|c| c.name).collect();
        let beyond = match (long, shapes.is_empty()) {
            (true, false) => format!(
                "a longer wave, what the fitted shapes ({}) represent; give the screw's lead, or measure a dense run over \
                 several leads",
                shapes.iter().map(|n| n.as_str()).collect::<Vec<_>>().join(", ")
            ),
            (true, true) => "a longer wave than the candidate's periods".to_string(),
            (false, _) => "a misfit faster than the periods these sample positions resolve (per-target scatter)".into(),
        };
        r.verdict = if long && !shapes.is_empty() { Verdict::Inseparable } else { Verdict::Noise };
        r.confused_with = if long { shapes } else { vec![] };
        r.note = Some(format!(
            "`{}` fits best at {} mm, an end of the periods searched: the fit still improves beyond the range, so \
             it is not identified at a period in range; the signal is {beyond}",
            r.effect,
            fmt_num(p * 1e3),
        ));
    }
    // A fitted period that other periods reproduce on these positions is not identified: the
    // claim is `inseparable` from its aliases (the data cannot say which one), with the advice.
    for r in ranking.iter_mut().filter(|r| r.verdict == Verdict::Significant) {
        let Some(&p) = r.params.get("period") else { continue };
        let Some(range) = period_range(r.effect) else { continue };
        let mut aliases = period_aliases(st, p, range);
        aliases.truncate(8);
        if aliases.is_empty() {
            continue;
        }
        let list: Vec<String> = aliases.iter().map(|q| format!("{} mm", fmt_num(q * 1e3))).collect();
        r.verdict = Verdict::Inseparable;
        r.note = Some(format!(
            "`{}` at a {} mm period fits these sample positions exactly as well as at {}: the period is not \
             identified. Targets every ≤ P/3 over a period P, irregular spacing or a dense run would separate them",
            r.effect,
            fmt_num(p * 1e3),
            list.join(", ")
        ));
        r.aliases = aliases;
    }
    // The cyclic-lead entry says which periods were not searched (and why), unless it has a note.
    if let Some(r) = ranking.iter_mut().find(|r| r.effect == EffectName::CyclicLead && r.note.is_none()) {
        r.note = restricted;
    }
    for n in unresolved {
        let note = unresolved_period_note(&f.st, n);
        notes.push(note.clone());
        ranking.push(RankedEffect {
            effect: n,
            delta_bic: 0.0,
            explained: 0.0,
            verdict: Verdict::Noise,
            params: BTreeMap::new(),
            confused_with: vec![],
            note: Some(note),
            aliases: vec![],
            p_value: None,
            searched: None,
            at_bound: vec![],
            shape_orders: EffectMap::new(),
        });
    }
    let mut shapes = shape_reports(&f.fs);
    if !st.chans.iter().any(|c| c.is_accel()) {
        for (_, s) in shapes.iter_mut().filter(|(_, s)| s.chosen_by != "model") {
            s.chosen_by += "; re-chosen by BIC with each candidate in the model (`shape_orders` of its ranking entry)";
        }
    }
    // A given order stiffer than the data show is itself a finding, named before any candidate.
    let stiff: Vec<String> = shapes
        .iter()
        .filter_map(|(n, s)| {
            s.bic_order
                .filter(|b| *b > s.order)
                .map(|b| format!("{n} needs more flexibility: order {} → {b} (BIC)", s.order))
        })
        .collect();
    let mut advice = advice(&ranking, nrms, Recording::of(st.chans));
    if !stiff.is_empty() {
        advice = format!(
            "{}; raise `order` (or remove it to let BIC choose) before adding effects. {advice}",
            stiff.join("; ")
        );
    }
    Ok(DiagnoseReport { normalized_rms: nrms, ranking, advice, notes, shapes, sigma: f.sigma })
}

/// Bonferroni over a diagnosis's candidates: the ranked group's p-value times `scale` (all
/// candidates / the group's), capped at 1; a significant entry above `alpha` becomes noise.
fn bonferroni(r: &mut RankedEffect, scale: f64, alpha: f64) {
    r.p_value = r.p_value.map(|p| (p * scale).min(1.0));
    if r.verdict == Verdict::Significant && r.p_value.is_some_and(|p| p > alpha) {
        r.verdict = Verdict::Noise;
    }
}

/// What `diagnose` needs to re-choose the shapes with one candidate in the model.
struct Reshape<'s, 'a> {
    st: &'s Stack<'a>,
    model: &'s Model,
    f: &'s Fitted<'a>,
    /// Weights 1/σ of the fit; σ of the significance.
    w: &'s [f64],
    sig: &'s [f64],
    fit_sigma: &'s Sigma,
    config: &'s DiagnoseConfig,
    /// Number of candidates of the diagnosis (Bonferroni).
    total: usize,
    /// The shapes' orders the cyclic lead was ranked against (the joint scan's), when capped.
    joint: Option<&'s [(EffectName, u32)]>,
    /// The free motions' order curves at the fitted orders, factored once for every candidate.
    curves: &'s [FactoredCurve],
}

impl Reshape<'_, '_> {
    /// The candidate ranked against the fit `fs` (its non-zero columns as the base, σ of the
    /// significance).
    fn rank_against(
        &self,
        fs: &FitState,
        cand: &Candidate,
    ) -> Result<vmt_estimators::modelcheck::Diagnosis, vmt_estimators::modelcheck::ModelCheckError> {
        let base: Vec<Vec<f64>> = fs.cols.iter().filter(|c| c.iter().any(|v| *v != 0.0)).cloned().collect();
        let sigma = Sigma::PerSample(self.sig.to_vec());
        let input =
            vmt_estimators::modelcheck::ResidualInput { residual: &fs.residual, sigma: &sigma, base_columns: &base };
        rank_candidates(&input, std::slice::from_ref(cand), self.config)
    }

    /// Shapes re-chosen for one candidate model: the orders of the model's fitted error motions
    /// re-chosen by BIC with the candidate's columns (at its fitted hyper-parameters) in the model
    /// ([`rechoose_orders`], capped below a periodic candidate's period), recorded in
    /// `shape_orders`. Where they differ from the orders the candidate was ranked against, the
    /// model is refitted at them and the candidate ranked again against that fit; its ΔBIC is then
    /// stated against the model as fitted (σ of the significance): ΔBIC_c + χ²_c − χ²_0 +
    /// (k_c − k_0)·ln n. It stays significant only if candidate + re-chosen shapes beat the model
    /// as fitted by the inseparable margin in BIC with σ unknown; otherwise the data cannot tell the
    /// candidate from the shapes' flexibility: `inseparable`, confused with the shapes it changed.
    fn apply(
        &self,
        r: &mut RankedEffect,
        name: EffectName,
        cand: Candidate,
        cols: &[Vec<f64>],
        k_hyper: usize,
        away: bool,
    ) -> Result<(), ModelCheckError> {
        let (st, f, w) = (self.st, self.f, self.w);
        let free = f.fs.free_orders();
        if free.is_empty() {
            return Ok(());
        }
        let start: Vec<(EffectName, u32)> = match self.joint {
            Some(j) if name == EffectName::CyclicLead => {
                free.iter().map(|&(m, o)| (m, j.iter().find(|(jm, _)| *jm == m).map_or(o, |(_, jo)| *jo))).collect()
            }
            Some(_) | None => free.clone(),
        };
        let period = period_range(name).and(r.params.get("period").copied());
        let (orders, bic_c) = rechoose_orders(st, self.model, &f.fs, w, cols, k_hyper, period, &start, self.curves)?;
        r.shape_orders = orders.iter().copied().collect();
        if orders == start {
            return Ok(());
        }
        let order_of = |_: usize, me: &ModelEffect| {
            let n = me.effect.name;
            let o = orders.iter().find(|(m, _)| *m == n).map(|(_, o)| *o).unwrap_or_else(|| {
                f.fs.shapes.iter().find(|c| c.name == n).map_or(me.order.unwrap_or(DEFAULT_ORDER), |c| c.order)
            });
            (o, None)
        };
        let fs_c = fit_model_held(st, self.model, self.fit_sigma, w, &order_of, &f.fs)?;
        let d = match self.rank_against(&fs_c, &cand) {
            Ok(d) => d,
            Err(ModelCheckError::NothingToExplain) => return Ok(()),
            Err(e) => return Err(e),
        };
        let Some(r2) = d.ranking.into_iter().next() else { return Ok(()) };
        let mut r2 = RankedEffect::typed(r2).map_err(|e| ModelCheckError::Invalid(e.to_string()))?;
        bonferroni(&mut r2, self.total as f64, self.config.family_alpha);
        // What the first ranking found among the candidates stands: explained away by a better one,
        // or inseparable from another candidate (the collinearity test compares candidates).
        if away && r2.verdict == Verdict::Significant {
            r2.verdict = Verdict::Noise;
        } else if r.verdict == Verdict::Inseparable && r2.verdict == Verdict::Significant && !r.confused_with.is_empty()
        {
            r2.verdict = Verdict::Inseparable;
            r2.confused_with = r.confused_with.clone();
        }
        let chi2 = |fs: &FitState| fs.residual.iter().zip(self.sig).map(|(r, s)| (r / s).powi(2)).sum::<f64>();
        r2.delta_bic += chi2(&fs_c) - chi2(&f.fs)
            + (fs_c.nonzero_columns() as f64 - f.fs.nonzero_columns() as f64) * (st.n as f64).ln();
        let delta_u = bic_c - f.fs.bic_unknown_sigma(w, st.n);
        let changed: Vec<(EffectName, u32, u32)> = free
            .iter()
            .filter_map(|&(m, o)| orders.iter().find(|(om, oo)| *om == m && *oo != o).map(|(_, oo)| (m, o, *oo)))
            .collect();
        let list: Vec<String> = changed.iter().map(|(m, a, b)| format!("{m} order {a} → {b}")).collect();
        // The candidate model at either set of orders: the one with the lower ΔBIC (σ of the
        // significance) is its evidence. (The lead's first ranking was against capped shapes, not
        // the model as fitted: its entry is always the re-ranked one.)
        let lead_capped = self.joint.is_some() && name == EffectName::CyclicLead;
        let better = lead_capped || r2.delta_bic < r.delta_bic;
        let said = format!(
            "shapes re-chosen by BIC with `{name}` in the model: {}; with it against the model as fitted: BIC \
             change (σ unknown) {delta_u:.1}{}",
            if list.is_empty() { "unchanged from the free orders".to_string() } else { list.join(", ") },
            if better { "" } else { "; its ΔBIC is lower at the free orders, which it keeps" }
        );
        if !better {
            r2 = r.clone();
            r2.note = None;
        }
        if r2.verdict == Verdict::Significant && delta_u >= -self.config.inseparable_margin && !changed.is_empty() {
            r2.verdict = Verdict::Inseparable;
            r2.confused_with = changed.iter().map(|(m, _, _)| *m).collect();
            r2.note = Some(format!(
                "{said}: `{name}` and the shapes' flexibility fit these data about as well, so the data cannot tell \
                 them apart"
            ));
        } else {
            r2.note = Some(match r2.note.take().or(r.note.take()) {
                Some(n) => format!("{n}; {said}"),
                None => said,
            });
        }
        r2.shape_orders = std::mem::take(&mut r.shape_orders);
        *r = r2;
        Ok(())
    }
}

/// The cyclic-lead entry of a diagnosis whose shapes were capped for it ([`LeadCap`]): ranked
/// against the model with its shapes at orders K* (`caps`: motion, cap, K*; from the joint scan
/// over the lead's periods, [`lead_shape_scan`]), searched only at periods shorter than their
/// shortest wavelength. It stays significant only if lead + capped shapes beat the model as fitted
/// (shapes at the orders BIC prefers without a lead) by `margin`: `delta` is that BIC change with
/// σ unknown. Otherwise the data cannot tell a lead at that period from a more flexible shape:
/// `inseparable`, confused with the shapes.
pub(crate) fn weigh_lead_against_shapes(
    r: &mut RankedEffect,
    caps: &[(EffectName, LeadCap, u32)],
    delta: f64,
    margin: f64,
) {
    let period = r.params.get("period").copied().unwrap_or(f64::NAN);
    let list: Vec<String> = caps
        .iter()
        .map(|(m, l, o)| {
            format!(
                "{m} at order {o} (shortest wavelength {} mm; BIC without a lead prefers order {})",
                fmt_num(l.basis.shortest_wavelength(l.span, *o) * 1e3),
                l.free_best
            )
        })
        .collect();
    let against = format!(
        "ranked against {} and searched only at shorter periods; lead + capped shapes against the model as \
         fitted: BIC change (σ unknown) {delta:.1}",
        list.join(", ")
    );
    if r.verdict != Verdict::Significant {
        r.note = Some(against);
    } else if delta < -margin {
        r.note = Some(format!("{against}: a lead at {} mm is the better explanation", fmt_num(period * 1e3)));
    } else {
        r.verdict = Verdict::Inseparable;
        r.confused_with = caps.iter().map(|(m, _, _)| *m).collect();
        r.note = Some(format!(
            "{against}: a lead at {} mm and the shapes' higher orders, whose wavelengths reach that period, fit \
             these data about as well, so the data cannot tell them apart",
            fmt_num(period * 1e3)
        ));
    }
}

/// Why a periodic effect is not searched on these positions, and what measurement would show it.
pub(crate) fn unresolved_period_note(st: &Stack, name: EffectName) -> String {
    // Called for periodic effects only (a `period` hyper-parameter).
    let range = catalogue_row(name).period.map_or("of its catalogue range", |p| p.text);
    let shortest = match shortest_resolvable_period(st) {
        Some(p) => format!("the shortest period they resolve is {} mm", fmt_num(p * 1e3)),
        None => "they resolve no period".to_string(),
    };
    format!(
        "{name} not searched: its periods {range} are not resolvable on these sample positions ({shortest}; \
         a shorter period is one of many aliases that fit the targets equally well). To see a period P, measure \
         targets every ≤ P/3 over at least one period (a dense run) or at irregular spacing"
    )
}

/// What measurement separates two effects that fit the same signature on these data, on the kind
/// of recording `rec` they were diagnosed from (a second laser for point tables; another speed, a
/// second sensor or a reversal for time series).
pub fn separating_measurement(a: EffectName, b: EffectName, rec: Recording) -> String {
    use EffectName::{Backlash, CyclicLead, GravityTilt, InterpolationError, Resonance, ServoLag};
    use EffectName::{Positioning, ScaleError, ThermalDrift, ThermalExpansion};
    let pair = |x: EffectName, y: EffectName| (a == x && b == y) || (a == y && b == x);
    let one = |x: EffectName| a == x || b == x;
    let angular = EffectName::is_angular;
    // A translation along the axis or across it: a translational error motion or the scale's error.
    let linear = |e: EffectName| e.is_translational() || e == ScaleError;
    let motion = EffectName::is_error_motion;
    // Time series: what separates two effects is another speed, a second sensor or a reversal.
    match rec {
        Recording::Accelerometer if one(GravityTilt) => {
            return "record constant-velocity passes at two or more speeds: a guideway's shape reaches an \
                    accelerometer as v²·E″(x), growing with the square of the speed, gravity through a tilt as \
                    g·tilt(x) at every speed"
                .into();
        }
        Recording::Accelerometer if one(Resonance) => {
            return "record passes at another speed: a structural mode rings at its own frequency in time whatever \
                    the speed, a guideway's wave at a fixed wavelength in position (its frequency moves with v)"
                .into();
        }
        Recording::Accelerometer if angular(a) || angular(b) => {
            return "mount a second accelerometer at another height or lateral offset: an angular error motion \
                    moves it in proportion to the offset, a translation does not"
                .into();
        }
        Recording::EncoderLog if one(Backlash) => {
            return "log a slow reversal with the linear scale and the motor encoder together: the table stands \
                    while the motor takes up the clearance"
                .into();
        }
        Recording::EncoderLog if pair(CyclicLead, InterpolationError) => {
            return "log the linear scale against the motor encoder at two speeds: a cyclic lead is in the \
                    transmission (scale − motor) at the screw's lead, an interpolation error in the scale alone at \
                    its signal period"
                .into();
        }
        Recording::EncoderLog if (one(CyclicLead) || one(InterpolationError)) && (motion(a) || motion(b)) => {
            return "log passes over a longer travel, or give the screw's lead (or the scale's signal period) as \
                    `period`: a periodic error repeats with the same period and phase along the whole travel, a \
                    shape's waves do not"
                .into();
        }
        Recording::EncoderLog if one(ServoLag) => {
            return "log passes at two or more speeds and both directions: a following error grows with the \
                    speed and changes sign with the direction, a position error does neither"
                .into();
        }
        Recording::PointTable | Recording::Accelerometer | Recording::EncoderLog => {}
    }
    if pair(ThermalExpansion, ScaleError) || pair(ThermalExpansion, Positioning) {
        "repeat the positioning test later, when the machine is warm (runs at different times): thermal expansion \
         grows with time, a scale error does not"
            .into()
    } else if one(ThermalDrift) {
        "record the readings over a longer time, or repeat the test after a pause: a drift grows with time".into()
    } else if (angular(a) && linear(b)) || (angular(b) && linear(a)) || (angular(a) && angular(b)) {
        "measure with a second laser at another height or lateral offset (a different Abbe offset), or with an \
         angular laser: an angular error motion scales with the offset, a translation does not"
            .into()
    } else if (a == CyclicLead && motion(b)) || (b == CyclicLead && motion(a)) {
        "measure dense runs (targets every ≤ P/3 over at least three periods P) at two or more places along \
         the travel: a lead repeats with the same period and phase everywhere, a shape does not; or give the \
         screw's lead as `period` of a fitted `cyclic_lead`"
            .into()
    } else if pair(CyclicLead, InterpolationError) {
        "measure at target spacings finer than the screw lead and than the scale's signal period".into()
    } else if one(Backlash) {
        "approach every target from both directions (bidirectional ISO 230-2 cycle)".into()
    } else {
        "measure at more positions, at other times or with a sensor at another offset, so that the two \
         signatures differ"
            .into()
    }
}

/// What a diagnosis's channels are, for the advice on a measurement that separates two effects
/// ([`separating_measurement`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Recording {
    /// Point tables (lasers, encoders at targets) and friction sweeps.
    PointTable,
    /// Accelerometer channels in constant-velocity passes.
    Accelerometer,
    /// Encoder time series (scale, motor encoder against the command).
    EncoderLog,
}

impl Recording {
    /// The recording of channels `chans`: accelerometers first, then encoder logs.
    pub(crate) fn of(chans: &[Channel]) -> Recording {
        if chans.iter().any(|c| c.is_accel()) {
            Recording::Accelerometer
        } else if chans.iter().any(|c| c.encoder.is_some()) {
            Recording::EncoderLog
        } else {
            Recording::PointTable
        }
    }
}

/// The advice text of a diagnosis.
pub(crate) fn advice(ranking: &[RankedEffect], nrms: f64, rec: Recording) -> String {
    let mut parts: Vec<String> = Vec::new();
    let sig: Vec<&RankedEffect> = ranking.iter().filter(|r| r.verdict == Verdict::Significant).collect();
    for r in &sig {
        parts.push(format!(
            "`{}` is significant (ΔBIC {:.1}, explains {:.0} % of the residual): add it with \
             `vmt add --effect {} --from-diagnosis`.",
            r.effect,
            r.delta_bic,
            100.0 * r.explained,
            r.effect
        ));
    }
    let mut seen: Vec<(EffectName, EffectName)> = Vec::new();
    for r in ranking.iter().filter(|r| r.verdict == Verdict::Inseparable) {
        for &o in &r.confused_with {
            // The pair in the order of the names.
            let key = if r.effect.as_str() < o.as_str() { (r.effect, o) } else { (o, r.effect) };
            if seen.contains(&key) {
                continue;
            }
            parts.push(format!(
                "`{}` and `{}` explain the residual equally well on these data and cannot be told apart: {}.",
                key.0,
                key.1,
                separating_measurement(key.0, key.1, rec)
            ));
            seen.push(key);
        }
    }
    for r in ranking.iter().filter(|r| r.verdict == Verdict::Inseparable && !r.aliases.is_empty()) {
        parts.extend(r.note.clone());
    }
    if parts.is_empty() {
        parts.push(format!("no missing effect is significant at this noise level (normalised RMS {nrms:.2})."));
        if nrms > 1.5 {
            parts.push(
                "The residual is above the noise but no catalogue effect explains it: look at the residual by \
                 position, direction and time in `vmt compare`, or fit an error motion with a richer basis."
                    .into(),
            );
        }
    }
    parts.join(" ")
}
