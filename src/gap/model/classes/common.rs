//! What several class families share: parameter vectors (shape increments, a member's
//! parameters, a gain and an offset), shapes on the records' knots and their change, the
//! reasons a class cannot be checked, and the zigzag test of a fitted shape.

use super::basis::Basis;
use super::knots::{Has, Knots, Needs};
use crate::gap::fit::lsq::ParamSpec;
use crate::gap::model::candidate::{Channel, Model};
use crate::gap::model::class::{ClassId, Variable};
use crate::gap::model::shape::{Shape, KNOTS};
use crate::gap::model::terms::{largest_signed, GainOffset};
use crate::model::effects::{EffectId, Subsystem};

/// A member's first parameter as the magnitude, in its unit.
pub fn member_magnitude(class: ClassId, m: &Model) -> (f64, &'static str) {
    match class.member().and_then(|id| Some((id, m.set.get(id)?))) {
        Some((id, v)) => (v[0], id.params()[0].unit),
        None => (0.0, ""),
    }
}

/// The channels of a subsystem's equation.
pub fn group_channels(s: Subsystem) -> Vec<Channel> {
    match s {
        Subsystem::TorqueCharacteristic => vec![Channel::Torque(0), Channel::Torque(1)],
        Subsystem::Thermal => vec![Channel::Temp(0), Channel::Temp(1), Channel::Temp(2)],
        Subsystem::Actuator => vec![Channel::Pos(0), Channel::Pos(1)],
        Subsystem::Engine => vec![Channel::Engine],
        Subsystem::Driveline => vec![],
    }
}

/// The increments of a shape, each within ±`bound` (solver scale `scale`).
pub fn shape_params(prefix: &str, bound: f64, scale: f64) -> Vec<ParamSpec> {
    (1..KNOTS)
        .map(|j| ParamSpec::new(format!("{prefix}.d{j}"), 0.0, -bound, bound, scale))
        .collect()
}

/// A library member's parameters, from its typical value within its bounds.
pub fn member_params(id: EffectId) -> Vec<ParamSpec> {
    id.params()
        .iter()
        .map(|ps| {
            let scale = (ps.plausible.1 - ps.plausible.0).abs().max(1e-12);
            ParamSpec::new(
                format!("{}.{}", id.as_str(), ps.name),
                ps.typical,
                ps.bounds.0,
                ps.bounds.1,
                scale,
            )
        })
        .collect()
}

/// A gain (1 ± `gain_span`) and an offset (± `offset_bound`, solver scale `offset_scale`).
pub fn gain_offset(
    class: ClassId,
    gain_span: f64,
    offset: &str,
    offset_bound: f64,
    offset_scale: f64,
) -> Vec<ParamSpec> {
    vec![
        ParamSpec::new(
            format!("{class}.gain"),
            1.0,
            1.0 - gain_span,
            1.0 + gain_span,
            gain_span / 15.0,
        ),
        ParamSpec::new(
            format!("{class}.{offset}"),
            0.0,
            -offset_bound,
            offset_bound,
            offset_scale,
        ),
    ]
}

/// The shape in `var` with increments `v` on the records' knots (none where `var` does not vary).
pub fn shape_on(knots: &Knots, var: Variable, v: &[f64]) -> Option<Shape> {
    knots.0.get(&var).map(|z| Shape::from_increments(*z, v))
}

/// Why a torque class cannot be fitted: no torque.
pub fn no_torque() -> String {
    "no slipping clutch torque in the records".into()
}

/// Why a thermal class cannot be fitted: no temperatures.
pub fn no_temperatures() -> String {
    "no plate / central-disk temperatures".into()
}

/// A shape class of the torque characteristic: it needs the torque and its variable varying.
pub fn torque_shape_checkable(var: Variable, knots: &Knots, has: Has) -> Option<String> {
    if !has(Needs::Torque) {
        return Some(no_torque());
    }
    (!knots.0.contains_key(&var)).then(|| format!("the records do not vary the {var}"))
}

/// A shape's change over its knots: the relative change of a multiplier 1 + s, the span of
/// the others; with its [`Basis`] over the knots' range.
pub fn shape_change(shape: Option<&Shape>, multiplier: bool) -> (f64, Basis) {
    let Some(s) = shape else {
        return (0.0, Basis::Parameter);
    };
    let (from, to) = (s.z[0], s.z[KNOTS - 1]);
    if multiplier {
        let m = (1.0 + s.v[KNOTS - 1]) / (1.0 + s.v[0]) - 1.0;
        (m, Basis::Ratio { from, to })
    } else {
        (s.span(), Basis::Change { from, to })
    }
}

/// Least-squares slope of the term through the knots.
pub fn slope(pts: &[(f64, f64)]) -> f64 {
    let n = pts.len() as f64;
    let mz = pts.iter().map(|p| p.0).sum::<f64>() / n;
    let mv = pts.iter().map(|p| p.1).sum::<f64>() / n;
    let sxy: f64 = pts.iter().map(|p| (p.0 - mz) * (p.1 - mv)).sum();
    let sxx: f64 = pts.iter().map(|p| (p.0 - mz).powi(2)).sum();
    if sxx > 0.0 {
        sxy / sxx
    } else {
        0.0
    }
}

/// A shape's points, when at least two: what a member's slope is read from.
pub fn points_of(shape: Option<Shape>) -> Vec<(f64, f64)> {
    shape.map(|s| s.points()).unwrap_or_default()
}

/// Increments smaller than this share of the curve's total variation are rounding, not a turn.
const TURN_SHARE: f64 = 0.02;

/// When a fitted shape turns more than once (its increments, leaving out those below
/// [`TURN_SHARE`] of the total variation, change sign twice or more), the sign of its total
/// change: the direction of the monotone curve it is refitted as. `None` for a curve that is
/// monotone or turns once (a peak, or the first segment's jump where the variable's low end
/// is invisible to the torque — a clamp load of zero transmits nothing).
pub fn zigzag_sign(d: &[f64]) -> Option<f64> {
    let tv: f64 = d.iter().map(|x| x.abs()).sum();
    let signs: Vec<bool> = d
        .iter()
        .filter(|x| x.abs() > TURN_SHARE * tv)
        .map(|x| *x > 0.0)
        .collect();
    let turns = signs.windows(2).filter(|w| w[0] != w[1]).count();
    (turns > 1).then(|| {
        if d.iter().sum::<f64>() >= 0.0 {
            1.0
        } else {
            -1.0
        }
    })
}

/// Position range over which a position reading error or the actuator transfer's is reported (mm).
pub const POSITION_READING_RANGE: (f64, f64) = (0.0, 6.0);

/// A gain-and-offset reading error's value of largest size over `range` (ends: it is straight).
pub fn largest_gain_error(g: Option<GainOffset>, reference: f64, range: (f64, f64)) -> f64 {
    g.map_or(0.0, |g| {
        largest_signed(
            [range.0, range.1]
                .into_iter()
                .map(|v| g.apply(v, reference) - v),
        )
    })
}

/// The first two parameters as a gain and an offset.
pub fn go(v: &[f64]) -> GainOffset {
    GainOffset {
        gain: v[0],
        offset: v[1],
    }
}
