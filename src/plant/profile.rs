//! Time profiles read from TOML files: the built-in driver of vehicle mode ([`Scenario`]: pedal,
//! brake, gear lever and road grade over time) and the x_to profile of the test rig
//! ([`RigProfile`]: the paper's Sect. 3.3 experiment — a number of partial engagements driven by
//! the same periodic x_to signal, then a cooling phase with both clutches open).
//!
//! Tables are piecewise linear in time ([`Table::linear`]) or held ([`Table::held`]); before the
//! first point the first value applies, after the last point the last value. Two points at the
//! same time make a step. `scripts/rig_partial_engagements.py` evaluates the same rig profile
//! files with the same rules, so an experiment runs identically over vcan and in process.

use super::error::{parse_toml, read_text, PlantError};
use crate::can::messages::GearLever;
use std::path::{Path, PathBuf};

/// A sampled function of time: points (t, value), t non-decreasing.
#[derive(Debug, Clone, PartialEq)]
pub struct Table {
    t: Vec<f64>,
    v: Vec<f64>,
}

impl Table {
    /// A table from points; `t` must be non-decreasing, both of equal non-zero length, finite.
    pub fn new(t: Vec<f64>, v: Vec<f64>) -> Result<Self, String> {
        if t.is_empty() || t.len() != v.len() {
            return Err(format!(
                "needs as many values ({}) as times ({}), at least one",
                v.len(),
                t.len()
            ));
        }
        for i in 0..t.len() {
            if !t[i].is_finite() || !v[i].is_finite() {
                return Err(format!("point {i} is not finite"));
            }
            if i > 0 && t[i] < t[i - 1] {
                return Err(format!("times must not decrease (index {i})"));
            }
        }
        Ok(Self { t, v })
    }

    /// A constant.
    pub fn constant(v: f64) -> Self {
        Self {
            t: vec![0.0],
            v: vec![v],
        }
    }

    /// Number of points before or at `x` (partition point).
    fn upto(&self, x: f64) -> usize {
        self.t.partition_point(|&ti| ti <= x)
    }

    /// Linear interpolation, held outside the points.
    pub fn linear(&self, x: f64) -> f64 {
        let j = self.upto(x);
        if j == 0 {
            return self.v[0];
        }
        if j == self.t.len() {
            return self.v[j - 1];
        }
        let i = j - 1;
        let f = (x - self.t[i]) / (self.t[j] - self.t[i]);
        self.v[i] + f * (self.v[j] - self.v[i])
    }

    /// True when the table holds one value over [a, b] (a ≤ b), by [`Self::linear`] and by
    /// [`Self::held`]: no point in (a, b] and the same value at both ends.
    pub fn constant_over(&self, a: f64, b: f64) -> bool {
        self.upto(a) == self.upto(b) && self.linear(a) == self.linear(b)
    }

    /// The value of the last point at or before `x` (the first value before the first point).
    pub fn held(&self, x: f64) -> f64 {
        let j = self.upto(x);
        self.v[j.saturating_sub(1)]
    }

    pub fn last_time(&self) -> f64 {
        self.t[self.t.len() - 1]
    }

    pub fn max_value(&self) -> f64 {
        self.v.iter().copied().fold(f64::NEG_INFINITY, f64::max)
    }
}

fn numbers(path: &Path, doc: &toml::Table, key: &str) -> Result<Option<Vec<f64>>, PlantError> {
    let Some(v) = doc.get(key) else {
        return Ok(None);
    };
    let arr = v
        .as_array()
        .ok_or_else(|| PlantError::key(path, key, "must be an array of numbers"))?;
    arr.iter()
        .enumerate()
        .map(|(i, x)| match x {
            toml::Value::Float(f) => Ok(*f),
            toml::Value::Integer(n) => Ok(*n as f64),
            toml::Value::Boolean(b) => Ok(if *b { 1.0 } else { 0.0 }),
            _ => Err(PlantError::key(
                path,
                format!("{key}[{i}]"),
                "must be a number",
            )),
        })
        .collect::<Result<Vec<_>, _>>()
        .map(Some)
}

fn number(path: &Path, doc: &toml::Table, key: &str) -> Result<Option<f64>, PlantError> {
    match doc.get(key) {
        None => Ok(None),
        Some(toml::Value::Float(f)) if f.is_finite() => Ok(Some(*f)),
        Some(toml::Value::Integer(n)) => Ok(Some(*n as f64)),
        Some(_) => Err(PlantError::key(path, key, "must be a finite number")),
    }
}

fn check_keys(
    path: &Path,
    doc: &toml::Table,
    prefix: &str,
    allowed: &[&str],
) -> Result<(), PlantError> {
    for k in doc.keys() {
        if !allowed.contains(&k.as_str()) {
            return Err(PlantError::key(
                path,
                format!("{prefix}{k}"),
                format!("unknown key (allowed: {})", allowed.join(", ")),
            ));
        }
    }
    Ok(())
}

/// A number's or a series' range ([`crate::ranges`]; each value of a series checked, `key[i]`
/// in the error).
fn in_range<B: crate::ranges::Bounded + ?Sized>(
    path: &Path,
    key: &str,
    value: &B,
    lo: f64,
    hi: f64,
) -> Result<(), PlantError> {
    crate::ranges::check("", key, value, lo, hi).map_err(|e| PlantError::range(path, e))
}

/// The built-in driver of vehicle mode: accelerator pedal (%, linear), brake (fraction 0..1,
/// held), gear lever (P/R/N/D, held) and road grade (%, linear) over time.
#[derive(Debug, Clone, PartialEq)]
pub struct Scenario {
    pub description: String,
    pub pedal_pct: Table,
    pub brake: Table,
    pub lever: Table,
    pub grade_pct: Table,
    /// Time of the last point (s).
    pub duration_s: f64,
    pub source: Option<PathBuf>,
}

/// What the driver does at one instant.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DriverSample {
    /// Pedal fraction 0..1.
    pub pedal: f64,
    /// Brake fraction 0..1.
    pub brake: f64,
    pub lever: GearLever,
    /// Grade, rise over run.
    pub grade: f64,
}

/// The scenario compiled into the binary (`config/scenarios/driver_launch.toml`).
pub(crate) const DEFAULT_SCENARIO_TOML: &str =
    include_str!("../../config/scenarios/driver_launch.toml");

impl Scenario {
    /// Parses a scenario file's text (`path` names it in errors).
    pub fn from_toml_str(path: &Path, text: &str) -> Result<Self, PlantError> {
        Self::from_table(path, &parse_toml(path, text)?).map_err(|e| e.located(path, text))
    }

    pub fn load(path: &Path) -> Result<Self, PlantError> {
        let mut s = Self::from_toml_str(path, &read_text(path)?)?;
        s.source = Some(path.to_path_buf());
        Ok(s)
    }

    /// The built-in launch scenario.
    pub fn builtin() -> Self {
        Self::from_toml_str(
            Path::new("config/scenarios/driver_launch.toml"),
            DEFAULT_SCENARIO_TOML,
        )
        .expect("the built-in scenario is valid (checked by a unit test)")
    }

    /// A scenario from a parsed table (errors name keys, not lines: see
    /// [`PlantError::located`]).
    pub(crate) fn from_table(path: &Path, doc: &toml::Table) -> Result<Self, PlantError> {
        check_keys(
            path,
            doc,
            "",
            &[
                "description",
                "t_s",
                "pedal_pct",
                "brake",
                "lever",
                "grade_pct",
            ],
        )?;
        let t = numbers(path, doc, "t_s")?
            .ok_or_else(|| PlantError::key(path, "t_s", "missing (times of the points, s)"))?;
        let n = t.len();
        let series = |key: &str, default: f64, lo: f64, hi: f64| -> Result<Table, PlantError> {
            let v = numbers(path, doc, key)?.unwrap_or_else(|| vec![default; n]);
            if v.len() != n {
                return Err(PlantError::key(
                    path,
                    key,
                    format!("has {} values, t_s has {n}", v.len()),
                ));
            }
            in_range(path, key, &v, lo, hi)?;
            Table::new(t.clone(), v).map_err(|e| PlantError::key(path, "t_s", e))
        };
        let pedal_pct = series("pedal_pct", 0.0, 0.0, 100.0)?;
        let brake = series("brake", 0.0, 0.0, 1.0)?;
        let grade_pct = series("grade_pct", 0.0, -50.0, 50.0)?;
        let lever_codes: Vec<f64> = match doc.get("lever") {
            None => vec![f64::from(GearLever::D as u8); n],
            Some(v) => {
                let arr = v
                    .as_array()
                    .ok_or_else(|| PlantError::key(path, "lever", "must be an array of P/R/N/D"))?;
                if arr.len() != n {
                    return Err(PlantError::key(
                        path,
                        "lever",
                        format!("has {} values, t_s has {n}", arr.len()),
                    ));
                }
                arr.iter()
                    .enumerate()
                    .map(|(i, x)| {
                        x.as_str()
                            .and_then(|s| GearLever::ALL.iter().find(|g| g.label() == s))
                            .map(|g| f64::from(*g as u8))
                            .ok_or_else(|| {
                                PlantError::key(
                                    path,
                                    format!("lever[{i}]"),
                                    "must be \"P\", \"R\", \"N\" or \"D\"",
                                )
                            })
                    })
                    .collect::<Result<_, _>>()?
            }
        };
        let lever =
            Table::new(t.clone(), lever_codes).map_err(|e| PlantError::key(path, "t_s", e))?;
        let description = doc
            .get("description")
            .and_then(|v| v.as_str())
            .unwrap_or("")
            .to_string();
        Ok(Scenario {
            description,
            duration_s: pedal_pct.last_time(),
            pedal_pct,
            brake,
            lever,
            grade_pct,
            source: None,
        })
    }

    /// The driver's inputs at time `t_s`.
    /// True when the driver does the same thing over [a, b] (see [`Table::constant_over`]).
    pub fn constant_over(&self, a: f64, b: f64) -> bool {
        [&self.pedal_pct, &self.brake, &self.lever, &self.grade_pct]
            .iter()
            .all(|t| t.constant_over(a, b))
    }

    pub fn sample(&self, t_s: f64) -> DriverSample {
        let code = self.lever.held(t_s).round().clamp(0.0, 3.0) as u64;
        DriverSample {
            pedal: self.pedal_pct.linear(t_s) / 100.0,
            brake: self.brake.held(t_s),
            lever: GearLever::from_raw(code).unwrap_or_default(),
            grade: self.grade_pct.linear(t_s) / 100.0,
        }
    }
}

/// A [`Scenario`] sampled at the steps of bus cycles: a cycle over which the driver holds still
/// ([`Scenario::constant_over`]) is sampled once; the samples are those of
/// [`Scenario::sample`], bit for bit.
#[derive(Debug, Clone, Copy, Default)]
pub(crate) struct CycleSampler {
    /// The cycle (index) the held sample belongs to, and the sample when the cycle is constant.
    cycle: Option<(u64, Option<DriverSample>)>,
}

impl CycleSampler {
    /// The driver at `t_s`, in cycle `cycle` spanning `[start_s, last_s]` (its first and last
    /// step).
    pub fn sample(
        &mut self,
        sc: &Scenario,
        t_s: f64,
        cycle: u64,
        start_s: f64,
        last_s: f64,
    ) -> DriverSample {
        let held = match self.cycle {
            Some((c, held)) if c == cycle => held,
            _ => {
                let held = sc
                    .constant_over(start_s, last_s)
                    .then(|| sc.sample(start_s));
                self.cycle = Some((cycle, held));
                held
            }
        };
        held.unwrap_or_else(|| sc.sample(t_s))
    }

    /// Whether the driver holds still over cycle `cycle`, when the sampler has looked at it.
    pub fn holds(&self, cycle: u64) -> Option<bool> {
        match self.cycle {
            Some((c, held)) if c == cycle => Some(held.is_some()),
            _ => None,
        }
    }
}

/// The rig experiment of the paper's Sect. 3.3: after `start_s`, `count` partial engagements of
/// one clutch, each following the same x_to(t) over one `period_s`, then `cooling_s` with both
/// clutches open. The dyno holds the input at `input_speed_rpm`.
#[derive(Debug, Clone, PartialEq)]
pub struct RigProfile {
    pub description: String,
    pub input_speed_rpm: f64,
    pub start_s: f64,
    /// Clutch driven (1 odd or 2 even).
    pub clutch: u8,
    pub count: u32,
    pub period_s: f64,
    /// x_to over one period (mm, linear), time from the start of the period.
    pub x_to: Table,
    pub cooling_s: f64,
    pub source: Option<PathBuf>,
}

/// A rig profile's `[engagement]` table, checked: which clutch, how many engagements, their
/// period and the position curve of one engagement.
struct RigEngagement {
    clutch: u8,
    count: u32,
    period_s: f64,
    x_to: Table,
}

impl RigEngagement {
    /// The `[engagement]` table of `doc` (required); every key checked, errors name it.
    fn from_doc(path: &Path, doc: &toml::Table) -> Result<Self, PlantError> {
        let eng = match doc.get("engagement") {
            Some(toml::Value::Table(t)) => t,
            _ => {
                return Err(PlantError::key(
                    path,
                    "engagement",
                    "missing table [engagement]",
                ))
            }
        };
        check_keys(
            path,
            eng,
            "engagement.",
            &["clutch", "count", "period_s", "t_s", "x_mm"],
        )?;
        let clutch = number(path, eng, "clutch")?.unwrap_or(1.0);
        if clutch != 1.0 && clutch != 2.0 {
            return Err(PlantError::key(path, "engagement.clutch", "must be 1 or 2"));
        }
        let count = number(path, eng, "count")?
            .ok_or_else(|| PlantError::key(path, "engagement.count", "missing"))?;
        in_range(path, "engagement.count", &count, 0.0, 10000.0)?;
        if count.fract() != 0.0 {
            return Err(PlantError::key(
                path,
                "engagement.count",
                "must be a whole number",
            ));
        }
        let period_s = number(path, eng, "period_s")?
            .ok_or_else(|| PlantError::key(path, "engagement.period_s", "missing"))?;
        in_range(path, "engagement.period_s", &period_s, 0.01, 3600.0)?;
        let t = numbers(path, eng, "t_s")?
            .ok_or_else(|| PlantError::key(path, "engagement.t_s", "missing"))?;
        let x = numbers(path, eng, "x_mm")?
            .ok_or_else(|| PlantError::key(path, "engagement.x_mm", "missing"))?;
        in_range(path, "engagement.x_mm", &x[..], 0.0, 8.0)?;
        in_range(path, "engagement.t_s", &t[..], 0.0, period_s)?;
        let x_to = Table::new(t, x).map_err(|e| PlantError::key(path, "engagement.t_s", e))?;
        Ok(RigEngagement {
            // 1 or 2, and a whole number in 0 ..= 10 000: checked above.
            clutch: clutch as u8,
            count: count as u32,
            period_s,
            x_to,
        })
    }
}

/// A rig profile's optional `[cooling]` table: the cooling time after the engagements (s).
fn cooling_s(path: &Path, doc: &toml::Table) -> Result<f64, PlantError> {
    match doc.get("cooling") {
        None => Ok(0.0),
        Some(toml::Value::Table(c)) => {
            check_keys(path, c, "cooling.", &["duration_s"])?;
            let d = number(path, c, "duration_s")?.unwrap_or(0.0);
            in_range(path, "cooling.duration_s", &d, 0.0, 36000.0)?;
            Ok(d)
        }
        Some(_) => Err(PlantError::key(path, "cooling", "must be a table")),
    }
}

impl RigProfile {
    pub fn from_toml_str(path: &Path, text: &str) -> Result<Self, PlantError> {
        Self::from_table(path, &parse_toml(path, text)?).map_err(|e| e.located(path, text))
    }

    pub fn load(path: &Path) -> Result<Self, PlantError> {
        let mut r = Self::from_toml_str(path, &read_text(path)?)?;
        r.source = Some(path.to_path_buf());
        Ok(r)
    }

    fn from_table(path: &Path, doc: &toml::Table) -> Result<Self, PlantError> {
        check_keys(
            path,
            doc,
            "",
            &[
                "description",
                "input_speed_rpm",
                "start_s",
                "engagement",
                "cooling",
            ],
        )?;
        let description = doc
            .get("description")
            .and_then(|v| v.as_str())
            .unwrap_or("")
            .to_string();
        let input_speed_rpm = number(path, doc, "input_speed_rpm")?.unwrap_or(2000.0);
        in_range(path, "input_speed_rpm", &input_speed_rpm, 0.0, 6000.0)?;
        let start_s = number(path, doc, "start_s")?.unwrap_or(0.0);
        in_range(path, "start_s", &start_s, 0.0, 3600.0)?;
        let e = RigEngagement::from_doc(path, doc)?;
        let cooling_s = cooling_s(path, doc)?;
        Ok(RigProfile {
            description,
            input_speed_rpm,
            start_s,
            clutch: e.clutch,
            count: e.count,
            period_s: e.period_s,
            x_to: e.x_to,
            cooling_s,
            source: None,
        })
    }

    /// Total duration: start, engagements, cooling (s).
    pub fn duration_s(&self) -> f64 {
        self.start_s + f64::from(self.count) * self.period_s + self.cooling_s
    }

    /// Index of the engagement running at `t_s`, if any.
    pub fn engagement_at(&self, t_s: f64) -> Option<u32> {
        if t_s < self.start_s {
            return None;
        }
        let k = ((t_s - self.start_s) / self.period_s).floor();
        (k < f64::from(self.count)).then_some(k as u32)
    }

    /// Requested bearing positions (clutch 1, clutch 2) at `t_s` (mm).
    pub fn x_ref(&self, t_s: f64) -> [f64; 2] {
        let mut x = [0.0; 2];
        if let Some(k) = self.engagement_at(t_s) {
            let tau = t_s - self.start_s - f64::from(k) * self.period_s;
            x[usize::from(self.clutch - 1)] = self.x_to.linear(tau);
        }
        x
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The cycle sampler gives every step of every cycle the scenario's own sample, bit for bit.
    #[test]
    fn cycle_sampler_is_the_scenario_sampled_at_every_step() {
        let root = Path::new(env!("CARGO_MANIFEST_DIR"));
        // Steps, ramps, a grade and knots off the 1 ms grid.
        let steps_and_ramps = "t_s = [0.0, 0.5, 1.0, 1.0, 2.0034, 3.5, 3.5, 4.0]\n\
            pedal_pct = [0.0, 0.0, 0.0, 60.0, 60.0, 10.0, 0.0, 0.0]\n\
            brake = [1.0, 1.0, 1.0, 0.0, 0.0, 0.0, 0.35, 0.35]\n\
            lever = [\"N\", \"D\", \"D\", \"D\", \"D\", \"D\", \"D\", \"R\"]\n\
            grade_pct = [0.0, 0.0, 0.0, 0.0, 5.0, 5.0, 5.0, 0.0]\n";
        let scenarios = [
            (
                "driver_launch",
                Scenario::load(&root.join("config/scenarios/driver_launch.toml")).unwrap(),
            ),
            (
                "steps_and_ramps",
                Scenario::from_toml_str(Path::new("s.toml"), steps_and_ramps).unwrap(),
            ),
        ];
        for (name, sc) in scenarios {
            let mut cs = CycleSampler::default();
            let (dt, n) = (1e-3, 10u64);
            let steps = (sc.duration_s / dt) as u64 + 20;
            for k in 0..steps {
                let cycle = k / n;
                let (t, a, b) = (
                    k as f64 * dt,
                    (cycle * n) as f64 * dt,
                    (cycle * n + n - 1) as f64 * dt,
                );
                let want = sc.sample(t);
                let got = cs.sample(&sc, t, cycle, a, b);
                assert!(
                    want.pedal.to_bits() == got.pedal.to_bits()
                        && want.brake.to_bits() == got.brake.to_bits()
                        && want.grade.to_bits() == got.grade.to_bits()
                        && want.lever == got.lever,
                    "{name} at {t} s: {got:?} against {want:?}"
                );
            }
        }
    }

    /// Constant over an interval: inside a flat segment, before the first and after the last
    /// point; not across a point (even between equal values), not on a slope.
    #[test]
    fn constant_over_flat_segments_only() {
        let t = Table::new(vec![0.0, 1.0, 2.0, 2.0], vec![5.0, 5.0, 7.0, 1.0]).unwrap();
        assert!(t.constant_over(0.2, 0.9));
        assert!(t.constant_over(-2.0, -1.0));
        assert!(t.constant_over(2.5, 4.0));
        assert!(t.constant_over(0.3, 0.3));
        assert!(!t.constant_over(0.5, 1.0));
        assert!(!t.constant_over(1.2, 1.5));
        assert!(!t.constant_over(1.9, 2.5));
        let tt = &t;
        let values =
            |a: f64, b: f64| (0..=100).map(move |k| tt.linear(a + (b - a) * k as f64 / 100.0));
        assert!(values(0.2, 0.9).all(|v| v == 5.0));
        assert!(values(1.2, 1.5).any(|v| v != t.linear(1.2)));
    }

    #[test]
    fn table_linear_held_and_steps() {
        let t = Table::new(vec![0.0, 1.0, 1.0, 3.0], vec![0.0, 10.0, 20.0, 0.0]).unwrap();
        assert_eq!(t.linear(-1.0), 0.0);
        assert_eq!(t.linear(0.5), 5.0);
        assert_eq!(t.linear(1.0), 20.0);
        assert_eq!(t.linear(2.0), 10.0);
        assert_eq!(t.linear(9.0), 0.0);
        assert_eq!(t.held(0.99), 0.0);
        assert_eq!(t.held(1.0), 20.0);
        assert!(Table::new(vec![1.0, 0.0], vec![0.0, 0.0]).is_err());
        assert!(Table::new(vec![0.0], vec![]).is_err());
    }

    #[test]
    fn builtin_scenario_is_valid() {
        let s = Scenario::builtin();
        assert!(s.duration_s > 5.0);
        let d = s.sample(0.0);
        assert!(d.pedal >= 0.0 && d.pedal <= 1.0);
    }

    #[test]
    fn scenario_errors_name_the_key() {
        let p = Path::new("x.toml");
        let e = Scenario::from_toml_str(p, "t_s = [0, 1]\npedal_pct = [0]\n").unwrap_err();
        assert!(
            matches!(&e, PlantError::Key { key, .. } if key == "pedal_pct"),
            "{e}"
        );
        let e = Scenario::from_toml_str(p, "t_s = [0, 1]\nlever = [\"D\", \"X\"]\n").unwrap_err();
        assert!(
            matches!(&e, PlantError::Key { key, .. } if key == "lever[1]"),
            "{e}"
        );
        let e = Scenario::from_toml_str(p, "t_s = [0, 1]\npedal_pct = [0, 120]\n").unwrap_err();
        assert!(
            matches!(&e, PlantError::Key { key, .. } if key == "pedal_pct[1]"),
            "{e}"
        );
        let e = Scenario::from_toml_str(p, "t_s = [0, 1]\nspeed = 3\n").unwrap_err();
        assert!(
            matches!(&e, PlantError::Key { key, .. } if key == "speed"),
            "{e}"
        );
    }

    #[test]
    fn rig_profile_periodic_engagements() {
        let text = "input_speed_rpm = 1500\nstart_s = 1.0\n[engagement]\nclutch = 2\ncount = 3\n\
                    period_s = 2.0\nt_s = [0.0, 0.5, 1.0]\nx_mm = [0.0, 5.0, 0.0]\n\
                    [cooling]\nduration_s = 10\n";
        let r = RigProfile::from_toml_str(Path::new("r.toml"), text).unwrap();
        assert_eq!(r.duration_s(), 17.0);
        assert_eq!(r.x_ref(0.5), [0.0, 0.0]);
        assert_eq!(r.x_ref(1.25), [0.0, 2.5]);
        assert_eq!(r.x_ref(5.5), [0.0, 5.0]);
        assert_eq!(r.engagement_at(6.9), Some(2));
        assert_eq!(r.x_ref(7.5), [0.0, 0.0]);
        let bad = text.replace("x_mm = [0.0, 5.0, 0.0]", "x_mm = [0.0, 9.0, 0.0]");
        let e = RigProfile::from_toml_str(Path::new("r.toml"), &bad).unwrap_err();
        assert!(
            matches!(&e, PlantError::Key { key, .. } if key == "engagement.x_mm[1]"),
            "{e}"
        );
    }
}
