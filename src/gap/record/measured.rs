//! One bench record as the diagnosis reads it: the measured series of a [`Dataset`] prepared
//! once (slip, friction power T_c·ω_fc and energy, the samples that inform the torque
//! characteristic (13), the event segmentation, the (16) state the replays start from), plain
//! data, and the model-free series derived from them that thousands of model evaluations share:
//! the slip dependence Q(ω) of (6) per clutch geometry, the sliding acceleration, the thermal
//! replay's windows per stride, the friction power's window means and its sites on a surface
//! rise's knots. Those are kept by value (a geometry's bits, a stride, knots' bits) and made on
//! first use; the corrections that change an input they read — the speeds of a speed-sensor
//! term, the friction power of a torque- or speed-sensor term — go through
//! [`Measured::with_speeds`] and [`Measured::with_power`], which start them anew.

use std::sync::Arc;

use crate::gap::model::shape::{Shape, KNOTS};
use crate::gap::record::memo::Memo;
use crate::gap::record::power_sites::PowerSites;
use crate::gap::record::series;
use crate::gap::record::slip_shapes::SlipShapes;
use crate::gap::record::windows::{PowerMeans, WindowSeries, Windows, XOrder};
use crate::model::clutch;
use crate::model::params::{ClutchParams, Params};
use crate::model::powertrain::ClutchContext;
use crate::model::thermal::Thermal5State;
use crate::records::dataset::{Col, Dataset};
use crate::records::events::{segment, SegmentOptions, Segmentation};

/// A measured series, shared: clones of a [`Measured`] (the sensor classes correct a few of its
/// inputs per evaluation) copy only what they change.
pub type Shared = Arc<[f64]>;

/// Measured quantities of one dataset, precomputed once.
#[derive(Debug, Clone)]
pub struct Measured {
    pub source: String,
    pub n: usize,
    pub dt: f64,
    pub time: Shared,
    pub x: [Shared; 2],
    pub slip: [Shared; 2],
    pub torque: [Shared; 2],
    pub pp: [Shared; 2],
    pub cd: Shared,
    pub th: Shared,
    pub w_f: Shared,
    /// Measured friction power T_c·ω_fc (W).
    pub power: [Shared; 2],
    /// Cumulative friction energy from the start of the first file of the sequence (J).
    pub e_cum: [Shared; 2],
    /// Position requests of each clutch, where logged (one logged column checks its actuator).
    pub x_req: [Option<Shared>; 2],
    pub t_e: Option<Shared>,
    pub w_out: Option<Shared>,
    pub gears: Option<[Shared; 2]>,
    pub valid: Arc<[bool]>,
    /// A test-rig record (input held by a dyno, output braked): the engine report is the dyno's.
    pub rig: bool,
    pub seg: Segmentation,
    /// Samples that inform the torque characteristic of each clutch (near or past the kiss
    /// point, or with measurable torque), valid only.
    pub torque_idx: [Arc<[usize]>; 2],
    /// The (16) state the free replays start from: [`Self::thermal_at`] the first sample of the
    /// thermocouples as read (corrected for a reading error where a term says so). A lag undone
    /// (θ + τ·dθ/dt) leaves it as it is: undoing a lag of seconds multiplies the readings' noise
    /// by τ over the derivative's ±1 s window, and an error in the slow states' start (the
    /// disks, the central disk: time constants of minutes) lasts the whole record. The lag term
    /// is applied to the replay from this reading on (the sensor settled at the start).
    pub start: Thermal5State,
    /// The sliding acceleration d|ω|/dt of each clutch at every sample
    /// ([`series::slide_acceleration`] of the measured slip).
    pub slides: Arc<[Vec<f64>; 2]>,
    /// Model-free series of the slip and the replay's other uncorrected inputs (x_to, θ_h, ω_f),
    /// made on first use and kept by value; shared by the record's clones, which no correction
    /// changes those inputs of.
    inputs_memo: InputsMemo,
    /// The same of the friction power and energy, which a torque-sensor correction replaces
    /// ([`Measured::with_power`] starts a new one).
    power_memo: PowerMemo,
}

impl Measured {
    /// Precomputes a dataset. `e0` is the friction energy dissipated before this file (J), so
    /// that energy-driven effects (wear) continue across files given in time order.
    pub fn new(d: &Dataset, p: &Params, e0: [f64; 2], seg: &SegmentOptions) -> Measured {
        let n = d.len();
        let slip = [d.slip(0), d.slip(1)];
        let slides = Arc::new([0, 1].map(|i| series::slide_acceleration(&slip[i], d.dt)));
        let torque = [d.req(Col::T1).to_vec(), d.req(Col::T2).to_vec()];
        let power: [Vec<f64>; 2] = [0, 1].map(|i| {
            (0..n)
                .map(|k| torque[i][k] * slip[i][k])
                .collect::<Vec<f64>>()
        });
        let e_cum = [0, 1].map(|i| series::cumulative_energy(&power[i], e0[i], d.dt));
        let x = [d.req(Col::X1).to_vec(), d.req(Col::X2).to_vec()];
        // Samples near or past the kiss point: x_to above x_ISP at a temperature well above the
        // hottest measured neighbour of the disk (the disk may run hotter than its plates), or
        // with measurable torque.
        let pp = [d.req(Col::Pp1), d.req(Col::Pp2)];
        let cdm = d.req(Col::Cd);
        let torque_idx = [0, 1].map(|i| {
            (0..n)
                .filter(|&k| {
                    let hot = pp[i][k].max(cdm[k]) + 80.0;
                    let gate = (0..=8)
                        .map(|j| {
                            clutch::x_isp(
                                &p.clutch,
                                p.clutch.theta_a_c + j as f64 * (hot - p.clutch.theta_a_c) / 8.0,
                            )
                        })
                        .fold(f64::INFINITY, f64::min)
                        - 0.4;
                    d.valid[k] && (x[i][k] >= gate || torque[i][k].abs() > 1.5)
                })
                .collect::<Vec<usize>>()
        });
        let x_req = [Col::X1Req, Col::X2Req].map(|c| d.get(c).map(Shared::from));
        let gears = match (d.get(Col::GearOdd), d.get(Col::GearEven)) {
            (Some(a), Some(b)) => Some([a.into(), b.into()]),
            _ => None,
        };
        let series = |v: [Vec<f64>; 2]| v.map(Shared::from);
        let rig = is_rig_record(d);
        let mut m = Measured {
            rig,
            source: d.source.clone(),
            n,
            dt: d.dt,
            time: d.time.as_slice().into(),
            x: series(x),
            slip: series(slip),
            torque: series(torque),
            pp: [d.req(Col::Pp1).into(), d.req(Col::Pp2).into()],
            cd: d.req(Col::Cd).into(),
            th: d.req(Col::Th).into(),
            w_f: d.req(Col::Wf).into(),
            power: series(power),
            e_cum: series(e_cum),
            x_req,
            t_e: d.get(Col::Te).map(Shared::from),
            w_out: d.get(Col::Wout).map(Shared::from),
            gears,
            valid: d.valid.as_slice().into(),
            seg: segment(&d.segment_series(), seg),
            torque_idx: torque_idx.map(Arc::from),
            start: Thermal5State::default(),
            slides,
            inputs_memo: InputsMemo::default(),
            power_memo: PowerMemo::default(),
        };
        m.start = m.thermal_at(0);
        m
    }

    /// Prepares files given in time order, carrying the friction energy across them.
    pub fn sequence(ds: &[Dataset], p: &Params, seg: &SegmentOptions) -> Vec<Measured> {
        Measured::sequence_from(ds, p, seg, [0.0; 2])
    }

    /// [`Measured::sequence`] starting at friction energies `e0` (J) already dissipated.
    pub fn sequence_from(
        ds: &[Dataset],
        p: &Params,
        seg: &SegmentOptions,
        e0: [f64; 2],
    ) -> Vec<Measured> {
        let mut e0 = e0;
        ds.iter()
            .map(|d| {
                let m = Measured::new(d, p, e0, seg);
                e0 = [0, 1].map(|i| *m.e_cum[i].last().unwrap_or(&e0[i]));
                m
            })
            .collect()
    }

    /// Measured temperatures at sample k as a (16) state, the disks at the mean of their
    /// neighbours (they are not measured). At the first sample the temperatures are taken over
    /// the open lead-in (up to 2 s before the first engagement) against sensor noise: the mean,
    /// or, when the lead-in drifts significantly (a preheated pack cooling), the intercept at
    /// t = 0 of a straight line fitted over it (a plain mean would start the replay late on that
    /// slope).
    pub fn thermal_at(&self, k: usize) -> Thermal5State {
        let avg = |v: &[f64]| -> f64 {
            if k != 0 {
                return v[k];
            }
            let first = self
                .seg
                .events
                .iter()
                .filter(|e| e.clutch.is_some())
                .map(|e| e.start)
                .min()
                .unwrap_or(self.n);
            let m = first.min((2.0 / self.dt) as usize).max(1).min(self.n);
            let mean = v[..m].iter().sum::<f64>() / m as f64;
            if m < 3 {
                return mean;
            }
            // Least-squares line over samples 0..m, evaluated at 0 when its slope is significant
            // (|t| > 3); otherwise the mean, which has a quarter of the intercept's variance.
            let kbar = (m - 1) as f64 / 2.0;
            let (mut sxy, mut sxx) = (0.0, 0.0);
            for (j, x) in v[..m].iter().enumerate() {
                let dk = j as f64 - kbar;
                sxy += dk * (x - mean);
                sxx += dk * dk;
            }
            let slope = sxy / sxx;
            let s2 = v[..m]
                .iter()
                .enumerate()
                .map(|(j, x)| (x - mean - slope * (j as f64 - kbar)).powi(2))
                .sum::<f64>()
                / (m - 2) as f64;
            if slope.abs() > 3.0 * (s2 / sxx).sqrt() {
                mean - slope * kbar
            } else {
                mean
            }
        };
        let (p1, p2, cd) = (avg(&self.pp[0]), avg(&self.pp[1]), avg(&self.cd));
        Thermal5State {
            pp1: p1,
            pp2: p2,
            c1: 0.5 * (p1 + cd),
            c2: 0.5 * (p2 + cd),
            cd,
        }
    }

    /// The samples `k0..k1` of the series a [`ClutchContext`] reads, for loops over many
    /// samples: indexing a [`Span`] needs one bounds check, not five, and the series a loop does
    /// not read are not loaded at all.
    pub fn span(&self, k0: usize, k1: usize) -> Span<'_> {
        let r = k0..k1;
        Span {
            x: [&self.x[0][r.clone()], &self.x[1][r.clone()]],
            slip: [&self.slip[0][r.clone()], &self.slip[1][r.clone()]],
            pp: [&self.pp[0][r.clone()], &self.pp[1][r.clone()]],
            cd: &self.cd[r.clone()],
            e_cum: [&self.e_cum[0][r.clone()], &self.e_cum[1][r]],
        }
    }

    /// Context of clutch `i` at sample `k` with an estimated disk temperature.
    #[inline]
    pub fn context(&self, i: usize, k: usize, theta_c: f64) -> ClutchContext {
        ClutchContext {
            clutch: i,
            x_to_mm: self.x[i][k],
            slip_radps: self.slip[i][k],
            theta_c,
            theta_pp: self.pp[i][k],
            theta_cd: self.cd[k],
            e_fric_j: self.e_cum[i][k],
        }
    }
}

/// The model-free series of one record kept by value ([`Measured`]'s memos): the slip shapes of
/// each clutch geometry asked for, the replay's windows of each stride and their order by
/// position.
#[derive(Debug, Clone, Default)]
struct InputsMemo {
    slip_shapes: Memo<[u64; 3], SlipShapes>,
    windows: Memo<usize, Windows>,
    /// Of the positions alone: a speed correction keeps it.
    x_order: Memo<usize, XOrder>,
}

/// The model-free series of one record's friction power: its window means of each stride, its
/// sites on each set of knots of a surface rise.
#[derive(Debug, Clone, Default)]
struct PowerMemo {
    means: Memo<usize, PowerMeans>,
    sites: Memo<[u64; KNOTS], PowerSites>,
}

impl Measured {
    /// The record with the friction power and energy `power`, `e_cum` in place of its own (a
    /// torque-sensor correction): what was kept of the old power, and the windows (which read
    /// the energy at their ends), are not carried over.
    pub fn with_power(mut self, power: [Shared; 2], e_cum: [Shared; 2]) -> Measured {
        self.power = power;
        self.e_cum = e_cum;
        self.inputs_memo.windows = Memo::default();
        self.power_memo = PowerMemo::default();
        self
    }

    /// The record with the slip of each clutch and the flywheel speed `w_f` in place of its own
    /// (a speed-sensor correction): the sliding acceleration is taken anew, and what was kept of
    /// the old speeds and power is not carried over (the caller sets the power with
    /// [`Measured::with_power`]).
    pub fn with_speeds(mut self, slip: [Shared; 2], w_f: Shared) -> Measured {
        self.slides = Arc::new([0, 1].map(|i| series::slide_acceleration(&slip[i], self.dt)));
        self.slip = slip;
        self.w_f = w_f;
        self.inputs_memo = InputsMemo {
            x_order: self.inputs_memo.x_order,
            ..InputsMemo::default()
        };
        self.power_memo = PowerMemo::default();
        self
    }

    /// Q(ω) of (6) at every sample for the clutch geometry of `p` (γ, R1, R2: no recalibration
    /// and no effect class moves them, so the thousands of models a diagnosis evaluates on the
    /// record share one), made on first use.
    pub fn slip_shapes(&self, p: &ClutchParams) -> Arc<SlipShapes> {
        let key = SlipShapes::key(p);
        self.inputs_memo
            .slip_shapes
            .get(key, || SlipShapes::new(p, [&self.slip[0], &self.slip[1]]))
    }

    /// The replay's windows of `stride` samples ([`Windows`]), made on first use.
    pub fn windows(&self, stride: usize) -> Arc<Windows> {
        self.inputs_memo.windows.get(stride, || {
            let x = [&self.x[0][..], &self.x[1][..]];
            let order = self
                .inputs_memo
                .x_order
                .get(stride, || XOrder::new(x, stride));
            let series = WindowSeries {
                x,
                slip: [&self.slip[0], &self.slip[1]],
                e_cum: [&self.e_cum[0], &self.e_cum[1]],
                th: &self.th,
                w_f: &self.w_f,
            };
            Windows::new(&series, order)
        })
    }

    /// The friction power's means over the replay's windows of `stride` samples, made on first
    /// use.
    pub fn power_means(&self, stride: usize) -> Arc<PowerMeans> {
        self.power_memo.means.get(stride, || {
            PowerMeans::new([&self.power[0], &self.power[1]], stride)
        })
    }

    /// The friction power of each sample located on the knots of `rise` ([`PowerSites`]),
    /// made on first use.
    pub fn power_sites(&self, rise: &Shape) -> Arc<PowerSites> {
        self.power_memo.sites.get(rise.z.map(f64::to_bits), || {
            PowerSites::locate(rise, [&self.power[0], &self.power[1]])
        })
    }
}

/// The series of a [`Measured`] a [`ClutchContext`] reads, over a range of samples
/// ([`Measured::span`]): sample `j` of the span is sample `k0 + j` of the record.
#[derive(Debug, Clone, Copy)]
pub struct Span<'a> {
    x: [&'a [f64]; 2],
    slip: [&'a [f64]; 2],
    pp: [&'a [f64]; 2],
    cd: &'a [f64],
    e_cum: [&'a [f64]; 2],
}

impl Span<'_> {
    /// Number of samples.
    #[inline]
    pub fn len(&self) -> usize {
        self.cd.len()
    }

    /// True when the span has no sample.
    #[inline]
    pub fn is_empty(&self) -> bool {
        self.cd.is_empty()
    }

    /// [`Measured::context`] of clutch `i` at the span's sample `j`.
    #[inline]
    pub fn context(&self, i: usize, j: usize, theta_c: f64) -> ClutchContext {
        ClutchContext {
            clutch: i,
            x_to_mm: self.x[i][j],
            slip_radps: self.slip[i][j],
            theta_c,
            theta_pp: self.pp[i][j],
            theta_cd: self.cd[j],
            e_fric_j: self.e_cum[i][j],
        }
    }
}

/// A test-rig record: the output held (|ω_out| < 1 rad/s) or, without ω_out, the input held at
/// one speed (the dyno), 99 % of the time. On the rig the engine report is the dyno's.
pub fn is_rig_record(d: &Dataset) -> bool {
    let n = d.len();
    if n == 0 {
        return false;
    }
    match d.get(Col::Wout) {
        Some(wo) => wo.iter().filter(|w| w.abs() < 1.0).count() as f64 >= 0.99 * n as f64,
        None => {
            let w_f = d.req(Col::Wf);
            let mut v = w_f.to_vec();
            v.sort_by(f64::total_cmp);
            let med = v[n / 2];
            w_f.iter().filter(|w| (*w - med).abs() < 2.0).count() as f64 >= 0.99 * n as f64
        }
    }
}

/// A short identification record of the nominal rig under `p` (6 engagements, 40 s, 10 ms
/// samples), for the tests of the replays and the predictions.
#[cfg(test)]
pub fn test_record(p: &Params) -> Measured {
    use crate::experiment::synth::{rig_frames, RigExperiment, SensorNoise};
    use crate::model::powertrain::Nominal;
    let exp = RigExperiment::identification(6, 40.0);
    let frames = rig_frames(p, Nominal, &exp, SensorNoise::default(), 3, 0.005).unwrap();
    let d = Dataset::from_records("rig", frames.into_iter().map(Ok), 0.01).unwrap();
    Measured::new(&d, p, [0.0; 2], &SegmentOptions::default())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Q of every sample is the one `clutch::slip_shape` computes, bit for bit; another γ gets
    /// its own entry (of its own numbers), the same geometry the same entry.
    #[test]
    fn slip_shapes_are_what_slip_shape_computes_per_geometry() {
        let p = Params::default();
        let m = test_record(&p);
        let a = m.slip_shapes(&p.clutch);
        let mut moving = 0;
        for i in 0..2 {
            for k in 0..m.n {
                let q = clutch::slip_shape(&p.clutch, m.slip[i][k]);
                assert_eq!(a.at(i, k).to_bits(), q.to_bits());
                moving += usize::from(m.slip[i][k] != 0.0);
            }
        }
        assert!(moving > 100, "the record slips at {moving} samples only");
        let mut other = p.clutch;
        other.gamma_s_per_m *= 2.0;
        let b = m.slip_shapes(&other);
        let k = (0..m.n).find(|&k| m.slip[0][k].abs() > 0.1).unwrap();
        assert_eq!(
            b.at(0, k).to_bits(),
            clutch::slip_shape(&other, m.slip[0][k]).to_bits()
        );
        assert_ne!(a.at(0, k).to_bits(), b.at(0, k).to_bits());
        assert_eq!(m.inputs_memo.slip_shapes.len(), 2);
        m.slip_shapes(&p.clutch);
        assert_eq!(m.inputs_memo.slip_shapes.len(), 2);
    }

    /// The sliding accelerations are the centred differences of |ω| over ±2 samples, computed
    /// here by hand.
    #[test]
    fn slides_are_the_sliding_acceleration() {
        let p = Params::default();
        let m = test_record(&p);
        let n = m.n;
        for i in 0..2 {
            let w = |k: usize| m.slip[i][k].abs();
            for k in 0..n {
                let (lo, hi) = (k.saturating_sub(2), (k + 2).min(n - 1));
                let want = (w(hi) - w(lo)) / ((hi - lo) as f64 * m.dt);
                assert_eq!(
                    m.slides[i][k].to_bits(),
                    want.to_bits(),
                    "clutch {i} sample {k}"
                );
            }
        }
        assert!(
            m.slides[0].iter().any(|v| v.abs() > 1.0),
            "the record never slides"
        );
    }

    /// Every sample's value at its kept site is the curve's value at the sample's power, bit for
    /// bit, for curves of other values on the same knots; other knots get their own entry; a
    /// record with another power ([`Measured::with_power`]) its own sites.
    #[test]
    fn a_kept_site_gives_the_curves_value_at_the_power() {
        let p = Params::default();
        let m = test_record(&p);
        let z = [0.0, 500.0, 1e3, 2e3, 4e3, 8e3, 16e3];
        let curves = [
            Shape {
                z,
                v: [0.0, 1.0, 3.0, 4.0, 9.0, 10.0, 30.0],
            },
            Shape {
                z,
                v: [0.0, -2.0, 0.5, 7.0, 7.5, 20.0, 21.0],
            },
        ];
        let sites = m.power_sites(&curves[0]);
        let mut segments = std::collections::BTreeSet::new();
        for c in &curves {
            for i in 0..2 {
                for k in 0..m.n {
                    let x = m.power[i][k].max(0.0);
                    assert_eq!(c.at(sites.at(i, k)).to_bits(), c.eval(x).to_bits());
                    segments.insert(sites.at(i, k).seg);
                }
            }
        }
        assert!(
            segments.len() >= 3,
            "the powers fall in segments {segments:?} only"
        );
        m.power_sites(&curves[1]);
        assert_eq!(m.power_memo.sites.len(), 1);
        let mut other = curves[0];
        other.z[1] = 600.0;
        m.power_sites(&other);
        assert_eq!(m.power_memo.sites.len(), 2);
        let doubled = [0, 1].map(|i| m.power[i].iter().map(|w| 2.0 * w).collect::<Shared>());
        let hot = m.clone().with_power(doubled, m.e_cum.clone());
        let k = (0..m.n).find(|&k| m.power[0][k] > 600.0).unwrap();
        let c = &curves[0];
        assert_eq!(
            c.at(hot.power_sites(c).at(0, k)).to_bits(),
            c.eval(2.0 * m.power[0][k]).to_bits()
        );
    }
}
