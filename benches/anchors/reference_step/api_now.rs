// The API of vmt-sim from ce7e26e (fidelity selectable) on, with LugreParams { steady: StribeckLaw }
// (b1e61cf^ and main in session 16): the cases of benches/sim_step.rs (cases_now.rs), the model on
// either engine.
use vmt_sim::axis_sim::{AxisSim, AxisTruth, GuideFriction};
use vmt_sim::drive::{BallScrewConfig, DriveConfig, FeedbackKind};
use vmt_sim::friction::{LugreParams, StribeckLaw};
use vmt_sim::geometry::ErrorMotions;
use vmt_sim::machine::{AxisConfig, AxisModel, Fidelity};
use vmt_sim::motion::Command;
use vmt_sim::profile::{Harmonic, Profile};
use vmt_sim::urdf::parse_urdf;

include!("cases_now.rs");

fn model(text: &str, cfg: &AxisConfig, fast: bool) -> Option<AxisModel> {
    let fidelity = if fast { Fidelity::Fast } else { Fidelity::Reference };
    Some(AxisModel::build(&parse_urdf(text).unwrap(), &AxisConfig { fidelity, ..cfg.clone() }).unwrap())
}
