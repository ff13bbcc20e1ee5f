//! Bench datasets for the diagnosis: one table of signals on a uniform time grid, loaded from a
//! CSV file with a header or from a candump `-l` log decoded with the bus contract.
//!
//! Columns (SI-like units in the names, DESIGN.md §6 and issue 7):
//! required `time_s, x_to1_mm, x_to2_mm, w_f_radps, w_c1_radps, w_c2_radps, T_c1_Nm, T_c2_Nm,
//! th_pp1_C, th_pp2_C, th_cd_C, th_h_C`; optional `T_e_Nm, w_out_radps, x_to1_req_mm,
//! x_to2_req_mm, gear_odd, gear_even, pedal_pct`. A missing optional column stays `None`, so the
//! subsystems that need it are reported as not checkable instead of guessed.
//!
//! Candump mapping (through the generated message types, never literal ids or scales):
//! `DCT_Actuators.Clutch{1,2}Pos` → x_to, `ENG_Status.EngSpeed` → ω_f and
//! `DCT_Sensors.InShaft{1,2}Speed`, `OutShaftSpeed` → ω_c, ω_out (rpm → rad/s),
//! `BENCH_Torque` → T_c, `BENCH_Temps` → θ_pp, θ_cd, `DCT_Sensors.HousingTemp` → θ_h,
//! `ENG_Status.EngTorqueAct` → T_e, `TCU_ClutchCmd` → x_to requests, `DCT_Actuators.Gear*Act`
//! → gears, `DRV_Pedal.AccelPedal` → pedal. `SIM_Truth` is simulation truth and is never read.
//! Frames that fail the E2E check (bad CRC, repeated counter, wrong DLC) are dropped and counted.
//!
//! Every signal is resampled onto a uniform grid by linear interpolation (gears by zero-order
//! hold; a grid point on a sample, to the rounding of the times, takes the sample as logged);
//! a grid point where a required signal has no sample within [`MAX_HOLD_S`] is marked
//! invalid in [`Dataset::valid`]. Errors name the file, line and column.
//!
//! Bad input is an error, not a plausible record (issue 17 item 7): a value outside its column's
//! physical range ([`Col::physical_range`]) or a gear outside the DBC value table
//! ([`Col::gear_signal`]); in a candump log a signal of a message read here outside its DBC range
//! or value table; a CSV time column going backwards or stepping less than [`MIN_STEP_S`]; a
//! candump timestamp going back more than [`MAX_HOLD_S`]. A gap in time (consecutive samples of
//! the clock — the CSV rows, the `ENG_Status` frames — further apart than the interpolation hold)
//! cuts the record into segments, each resampled on its own: nothing is filled, memory stays
//! proportional to the samples present. [`Segments`] (the loader of the `gap` and `identify`
//! commands) keeps the segments that last at least [`MIN_RECORD_S`] and requires one clutch
//! engagement in the file; the single-record constructors ([`Dataset::load`],
//! [`Dataset::from_csv`], …) refuse a record with gaps ([`DatasetError::Gaps`]).

use crate::can::candump::{parse_canonical, parse_line, LineError, LogRecord};
use crate::can::codec::{CodecError, SignalDef};
use crate::can::e2e::{is_protected, E2eChecker, E2eConfig, E2eError};
use crate::can::messages::{ids, message_def, DctActuators, Message};
use crate::model::gear::Gear;
use crate::records::events::{self, EventKind, SegmentOptions, SegmentSeries};
use embedded_can::Frame as _;
use std::io::BufRead;
use std::path::Path;

/// rpm → rad/s.
pub const RPM_TO_RADPS: f64 = std::f64::consts::PI / 30.0;
/// Longest interval (s) over which a signal is interpolated before grid points are invalid.
pub const MAX_HOLD_S: f64 = 0.055;
/// Default resampling step (s): the cycle of the plant's sensor frames in the contract.
pub const DEFAULT_DT_S: f64 = crate::can::messages::DctSensors::CYCLE_MS as f64 * 1e-3;
/// Shortest step (s) between two CSV rows: closer samples (or a median step below it) are not a
/// bench record (a duplicated row, a time column in the wrong unit).
pub const MIN_STEP_S: f64 = 1e-4;
/// Shortest record or segment (s) that holds one engagement with the open time around it (an
/// event block, `events.rs`): a launch slips for about a second, the rig's engagements last
/// 2–5 s, and the event segmentation reports open phases from 2 s (`min_open_s`).
pub const MIN_RECORD_S: f64 = 2.0;
/// Physical range of the temperatures (°C): thermocouples and housing sensor.
pub const TEMP_RANGE_C: (f64, f64) = (-60.0, 600.0);
/// Largest |throw-out bearing position| (mm), measured or requested: the stroke is about 10 mm;
/// beyond 100 mm the column is in another unit (µm) or broken.
pub const MAX_POSITION_MM: f64 = 100.0;
/// Largest |shaft speed| (rad/s), ≈ 19 100 rpm: twice any passenger-car engine or input shaft
/// (the DBC's ranges stop at 10 000 rpm and 8 192 rpm).
pub const MAX_SPEED_RADPS: f64 = 2000.0;
/// Largest |torque| (N·m) of a clutch or the engine: ten times a passenger-car clutch's capacity,
/// three times the DBC's ±3 276.8 N·m.
pub const MAX_TORQUE_NM: f64 = 10_000.0;

/// The columns of a dataset.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Col {
    X1,
    X2,
    Wf,
    Wc1,
    Wc2,
    T1,
    T2,
    Pp1,
    Pp2,
    Cd,
    Th,
    Te,
    Wout,
    X1Req,
    X2Req,
    GearOdd,
    GearEven,
    Pedal,
}

/// Number of data columns (time excluded).
pub const NCOL: usize = 18;

impl Col {
    /// Every column in order.
    pub const ALL: [Col; NCOL] = [
        Col::X1,
        Col::X2,
        Col::Wf,
        Col::Wc1,
        Col::Wc2,
        Col::T1,
        Col::T2,
        Col::Pp1,
        Col::Pp2,
        Col::Cd,
        Col::Th,
        Col::Te,
        Col::Wout,
        Col::X1Req,
        Col::X2Req,
        Col::GearOdd,
        Col::GearEven,
        Col::Pedal,
    ];

    /// CSV header name.
    pub fn name(self) -> &'static str {
        match self {
            Col::X1 => "x_to1_mm",
            Col::X2 => "x_to2_mm",
            Col::Wf => "w_f_radps",
            Col::Wc1 => "w_c1_radps",
            Col::Wc2 => "w_c2_radps",
            Col::T1 => "T_c1_Nm",
            Col::T2 => "T_c2_Nm",
            Col::Pp1 => "th_pp1_C",
            Col::Pp2 => "th_pp2_C",
            Col::Cd => "th_cd_C",
            Col::Th => "th_h_C",
            Col::Te => "T_e_Nm",
            Col::Wout => "w_out_radps",
            Col::X1Req => "x_to1_req_mm",
            Col::X2Req => "x_to2_req_mm",
            Col::GearOdd => "gear_odd",
            Col::GearEven => "gear_even",
            Col::Pedal => "pedal_pct",
        }
    }

    /// Column by CSV name.
    pub fn from_name(s: &str) -> Option<Col> {
        Col::ALL.into_iter().find(|c| c.name() == s)
    }

    /// Required columns must be present in every file.
    pub fn required(self) -> bool {
        (self as usize) <= Col::Th as usize
    }

    /// Discrete columns are resampled by zero-order hold.
    pub fn discrete(self) -> bool {
        matches!(self, Col::GearOdd | Col::GearEven)
    }

    /// Commands (requests) take effect at the first cycle at or after their timestamp: they are
    /// resampled by zero-order hold (a request logged after a cycle's sensor frames counts from
    /// the next cycle, as the plant latches it).
    pub fn command(self) -> bool {
        matches!(self, Col::X1Req | Col::X2Req | Col::Pedal)
    }

    /// Physical range `(min, max, unit)` of a column: a value outside it is impossible (a unit
    /// error, a broken sensor, a corrupted file), not a measurement. Temperatures −60…600 °C,
    /// pedal 0…100 %, positions ±[`MAX_POSITION_MM`], speeds ±[`MAX_SPEED_RADPS`], torques
    /// ±[`MAX_TORQUE_NM`]. Gears have none: they follow the DBC value table
    /// ([`Col::gear_signal`]).
    pub fn physical_range(self) -> Option<(f64, f64, &'static str)> {
        match self {
            Col::X1 | Col::X2 | Col::X1Req | Col::X2Req => {
                Some((-MAX_POSITION_MM, MAX_POSITION_MM, "mm"))
            }
            Col::Wf | Col::Wc1 | Col::Wc2 | Col::Wout => {
                Some((-MAX_SPEED_RADPS, MAX_SPEED_RADPS, "rad/s"))
            }
            Col::T1 | Col::T2 | Col::Te => Some((-MAX_TORQUE_NM, MAX_TORQUE_NM, "N·m")),
            Col::Pp1 | Col::Pp2 | Col::Cd | Col::Th => Some((TEMP_RANGE_C.0, TEMP_RANGE_C.1, "°C")),
            Col::Pedal => Some((0.0, 100.0, "%")),
            Col::GearOdd | Col::GearEven => None,
        }
    }

    /// The resolution of the column as the bus carries it: its DBC signal's factor in the
    /// column's unit (gears: 1).
    pub fn resolution(self) -> f64 {
        use crate::can::messages::{
            BenchTemps as Bt, BenchTorque as Bq, DctActuators as A, DctSensors as S, DrvPedal as P,
            EngStatus as E, TcuClutchCmd as C,
        };
        let rpm = RPM_TO_RADPS;
        match self {
            Col::X1 => A::clutch1_pos_def().factor,
            Col::X2 => A::clutch2_pos_def().factor,
            Col::X1Req => C::clutch1_pos_req_def().factor,
            Col::X2Req => C::clutch2_pos_req_def().factor,
            Col::Wf => E::eng_speed_def().factor * rpm,
            Col::Te => E::eng_torque_act_def().factor,
            Col::Wc1 => S::in_shaft1_speed_def().factor * rpm,
            Col::Wc2 => S::in_shaft2_speed_def().factor * rpm,
            Col::Wout => S::out_shaft_speed_def().factor * rpm,
            Col::Th => S::housing_temp_def().factor,
            Col::T1 => Bq::clutch1_torque_def().factor,
            Col::T2 => Bq::clutch2_torque_def().factor,
            Col::Pp1 => Bt::pressure_plate1_temp_def().factor,
            Col::Pp2 => Bt::pressure_plate2_temp_def().factor,
            Col::Cd => Bt::central_disk_temp_def().factor,
            Col::Pedal => P::accel_pedal_def().factor,
            Col::GearOdd | Col::GearEven => 1.0,
        }
    }

    /// The DBC signal whose value table a gear column follows (`DCT_Actuators.GearOddAct`,
    /// `GearEvenAct`, from the generated contract).
    pub fn gear_signal(self) -> Option<&'static SignalDef> {
        match self {
            Col::GearOdd => Some(DctActuators::gear_odd_act_def()),
            Col::GearEven => Some(DctActuators::gear_even_act_def()),
            _ => None,
        }
    }

    /// Whether `v` is possible in this column.
    fn check(self, v: f64) -> Result<(), Impossible> {
        if let Some((min, max, unit)) = self.physical_range() {
            if !(min..=max).contains(&v) {
                return Err(Impossible::Range { min, max, unit });
            }
        }
        if let Some(s) = self.gear_signal() {
            if !s.values.iter().any(|(raw, _)| *raw as f64 == v) {
                return Err(Impossible::Table(s));
            }
        }
        Ok(())
    }

    fn idx(self) -> usize {
        self as usize
    }

    /// Column of clutch `i` (0/1) among a pair.
    pub fn x(i: usize) -> Col {
        [Col::X1, Col::X2][i]
    }
    pub fn wc(i: usize) -> Col {
        [Col::Wc1, Col::Wc2][i]
    }
    pub fn torque(i: usize) -> Col {
        [Col::T1, Col::T2][i]
    }
    pub fn pp(i: usize) -> Col {
        [Col::Pp1, Col::Pp2][i]
    }
    pub fn x_req(i: usize) -> Col {
        [Col::X1Req, Col::X2Req][i]
    }
}

/// Errors of loading a dataset. Positions are 1-based; `column` is the header name.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum DatasetError {
    #[error("{file}: cannot read")]
    Io {
        file: String,
        #[source]
        source: crate::io_error::IoError,
    },
    #[error("{file}: empty file (expected a header line)")]
    Empty { file: String },
    /// What the `csv` reader reports (through `std::io::Error`, which wraps it: an error here is
    /// `Clone` and `PartialEq`).
    #[error("{file}:{line}: not readable as CSV")]
    Csv {
        file: String,
        line: usize,
        #[source]
        source: crate::io_error::IoError,
    },
    #[error("{file}:{line}: missing required column `{column}`")]
    MissingColumn {
        file: String,
        line: usize,
        column: String,
    },
    #[error("{file}:{line}: column {index} `{column}` appears twice")]
    DuplicateColumn {
        file: String,
        line: usize,
        index: usize,
        column: String,
    },
    #[error("{file}:{line}: expected {expected} fields as in the header, found {found}")]
    FieldCount {
        file: String,
        line: usize,
        expected: usize,
        found: usize,
    },
    #[error("{file}:{line}: column {index} `{column}`: `{text}` is not a finite number")]
    BadNumber {
        file: String,
        line: usize,
        index: usize,
        column: String,
        text: String,
    },
    #[error(
        "{file}:{line}: column {index} `time_s`: {} s goes backwards (previous row {} s)",
        num(.value),
        num(.previous)
    )]
    TimeOrder {
        file: String,
        line: usize,
        index: usize,
        value: f64,
        previous: f64,
    },
    #[error(
        "{file}:{line}: column {index} `time_s`: {} s is {} ms after the previous row ({} s): \
         steps below {} ms are not a bench record",
        num(.value),
        num(&(1e3 * (.value - .previous))),
        num(.previous),
        num(&(1e3 * MIN_STEP_S))
    )]
    TimeStep {
        file: String,
        line: usize,
        index: usize,
        value: f64,
        previous: f64,
    },
    #[error(
        "{file}:{line}: column {index} `{column}`: {} {unit} is outside the physical range {}…{} {unit}",
        num(.value),
        num(.min),
        num(.max)
    )]
    OutOfRange {
        file: String,
        line: usize,
        index: usize,
        column: String,
        value: f64,
        min: f64,
        max: f64,
        unit: &'static str,
    },
    #[error(
        "{file}:{line}: column {index} `{column}`: {} is not in the DBC value table of {signal} ({table})",
        num(.value)
    )]
    NotInTable {
        file: String,
        line: usize,
        index: usize,
        column: String,
        value: f64,
        signal: String,
        table: String,
    },
    #[error(
        "{file}:{line}: signal {signal}: {} {unit} is outside the DBC range {}…{} {unit}",
        num(.value),
        num(.min),
        num(.max)
    )]
    SignalRange {
        file: String,
        line: usize,
        signal: String,
        value: f64,
        min: f64,
        max: f64,
        unit: String,
    },
    #[error(
        "{file}:{line}: signal {signal}: raw value {raw} is not in the DBC value table ({table})"
    )]
    SignalValue {
        file: String,
        line: usize,
        signal: String,
        raw: u64,
        table: String,
    },
    #[error(
        "{file}:{line}: timestamp goes back {} s (to {} s after the first frame, after {} s)",
        num(&(.previous - .value)),
        num(.value),
        num(.previous)
    )]
    LogTimeOrder {
        file: String,
        line: usize,
        value: f64,
        previous: f64,
    },
    #[error(
        "{file}: the record lasts {} s, shorter than one engagement with the open time around it \
         ({} s)",
        num(.duration_s),
        num(.min_s)
    )]
    RecordTooShort {
        file: String,
        duration_s: f64,
        min_s: f64,
    },
    #[error(
        "{file}: gaps in time cut the record into {segments} segments and none lasts one \
         engagement ({} s; the longest {} s)",
        num(.min_s),
        num(.longest_s)
    )]
    NoUsableSegment {
        file: String,
        segments: usize,
        longest_s: f64,
        min_s: f64,
    },
    #[error(
        "{file}: no engagement: neither clutch torque (T_c1_Nm, T_c2_Nm) exceeds {} N·m for \
         {} s, there is nothing to identify or diagnose",
        num(.torque_on),
        num(.min_s)
    )]
    NoEngagement {
        file: String,
        torque_on: f64,
        min_s: f64,
    },
    #[error(
        "{file}:{line}: a gap in time ({} s → {} s) cuts the record into {segments} segments; \
         load it as segments (`Segments`)",
        num(.from_s),
        num(.to_s)
    )]
    Gaps {
        file: String,
        line: usize,
        from_s: f64,
        to_s: f64,
        segments: usize,
    },
    #[error("{file}: {rows} sample(s) — at least {min} are needed")]
    TooShort {
        file: String,
        rows: usize,
        min: usize,
    },
    #[error("{file}:{line}: malformed candump line")]
    LogLine {
        file: String,
        line: usize,
        #[source]
        source: LineError,
    },
    #[error("{file}: no valid {message} frame in the log: column(s) {columns} unavailable")]
    MissingMessage {
        file: String,
        message: &'static str,
        columns: String,
    },
    #[error("{file}: the required signals never overlap in time")]
    NoOverlap { file: String },
    #[error("{file}: {source}")]
    Mf4 {
        file: String,
        #[source]
        source: crate::can::mf4::Mf4Error,
    },
}

/// Why a value is impossible in its column.
enum Impossible {
    Range {
        min: f64,
        max: f64,
        unit: &'static str,
    },
    Table(&'static SignalDef),
}

impl Impossible {
    fn at(self, file: &str, line: usize, index: usize, c: Col, value: f64) -> DatasetError {
        match self {
            Impossible::Range { min, max, unit } => DatasetError::OutOfRange {
                file: file.into(),
                line,
                index,
                column: c.name().into(),
                value,
                min,
                max,
                unit,
            },
            Impossible::Table(s) => DatasetError::NotInTable {
                file: file.into(),
                line,
                index,
                column: c.name().into(),
                value,
                signal: format!("{}.{}", DctActuators::NAME, s.name),
                table: value_table(s),
            },
        }
    }
}

/// A DBC value table as `0 N, 1 G1, …`.
fn value_table(s: &SignalDef) -> String {
    s.values
        .iter()
        .map(|(raw, label)| format!("{raw} {label}"))
        .collect::<Vec<_>>()
        .join(", ")
}

/// A number for a message: shortest round-trip form, with a real minus sign.
fn num(v: &f64) -> String {
    let s = if v.abs() >= 1e12 {
        format!("{v:e}")
    } else if v.fract() == 0.0 || v.abs() < 1e-3 {
        format!("{v}")
    } else {
        // Enough digits for a bench value, without the binary noise of a difference.
        let t = format!("{v:.6}");
        t.trim_end_matches('0').trim_end_matches('.').to_string()
    };
    s.replace('-', "\u{2212}")
}

/// What the loader saw besides the samples.
#[derive(Debug, Clone, Default, PartialEq, serde::Serialize)]
pub struct LoadStats {
    /// Input rows (CSV) or frames (candump).
    pub records: usize,
    /// Frames dropped by the E2E check.
    pub dropped_e2e: usize,
    /// Frames not decodable with the contract (unknown id, wrong DLC, value out of range).
    pub undecodable: usize,
    /// SIM_Truth frames seen and ignored.
    pub ignored_truth: usize,
    /// Unknown CSV columns, ignored.
    pub ignored_columns: Vec<String>,
    /// Grid points without a fresh sample of every required signal, or with a bench signal
    /// clipped at its DBC range limit.
    pub invalid_points: usize,
}

/// A uniformly sampled bench record.
#[derive(Debug, Clone, PartialEq)]
pub struct Dataset {
    /// File the data came from (for messages and reports).
    pub source: String,
    /// Sample times (s), uniform, starting at the first common sample.
    pub time: Vec<f64>,
    /// Grid step (s).
    pub dt: f64,
    cols: Vec<Option<Vec<f64>>>,
    /// False where a required signal had no fresh sample (a gap in the log).
    pub valid: Vec<bool>,
    pub stats: LoadStats,
    /// Time of the first sample on the file's clock (s): CSV `time_s`, candump seconds since the
    /// first frame; 0 for a record built in memory. A segment after a gap starts later.
    pub start_s: f64,
}

impl Dataset {
    /// Builds a dataset from uniformly sampled columns (e.g. a simulation). Every required
    /// column must be present and every column must have `time.len()` samples.
    pub fn from_columns(
        source: impl Into<String>,
        dt: f64,
        columns: Vec<(Col, Vec<f64>)>,
    ) -> Result<Dataset, DatasetError> {
        let source = source.into();
        let mut cols: Vec<Option<Vec<f64>>> = vec![None; NCOL];
        let mut n = None;
        for (c, v) in columns {
            if let Some(n) = n {
                if v.len() != n {
                    return Err(DatasetError::FieldCount {
                        file: source,
                        line: 0,
                        expected: n,
                        found: v.len(),
                    });
                }
            }
            n = Some(v.len());
            cols[c.idx()] = Some(v);
        }
        let n = n.unwrap_or(0);
        for c in Col::ALL.iter().filter(|c| c.required()) {
            if cols[c.idx()].is_none() {
                return Err(DatasetError::MissingColumn {
                    file: source,
                    line: 0,
                    column: c.name().into(),
                });
            }
        }
        if n < 2 {
            return Err(DatasetError::TooShort {
                file: source,
                rows: n,
                min: 2,
            });
        }
        Ok(Dataset {
            source,
            time: (0..n).map(|k| k as f64 * dt).collect(),
            dt,
            cols,
            valid: vec![true; n],
            stats: LoadStats::default(),
            start_s: 0.0,
        })
    }

    /// Number of samples.
    pub fn len(&self) -> usize {
        self.time.len()
    }

    pub fn is_empty(&self) -> bool {
        self.time.is_empty()
    }

    /// Duration (s).
    pub fn duration(&self) -> f64 {
        self.dt * self.len().saturating_sub(1) as f64
    }

    /// A column, if present.
    pub fn get(&self, c: Col) -> Option<&[f64]> {
        self.cols[c.idx()].as_deref()
    }

    /// A required column (always present after loading).
    pub fn req(&self, c: Col) -> &[f64] {
        debug_assert!(c.required());
        self.cols[c.idx()].as_deref().unwrap_or(&[])
    }

    pub fn has(&self, c: Col) -> bool {
        self.cols[c.idx()].is_some()
    }

    /// Replaces or adds a column (same length).
    pub fn set(&mut self, c: Col, v: Vec<f64>) {
        debug_assert_eq!(v.len(), self.len());
        self.cols[c.idx()] = Some(v);
    }

    /// Removes an optional column.
    pub fn remove(&mut self, c: Col) {
        if !c.required() {
            self.cols[c.idx()] = None;
        }
    }

    /// Present columns, in order.
    pub fn columns(&self) -> Vec<Col> {
        Col::ALL.into_iter().filter(|c| self.has(*c)).collect()
    }

    /// Slip of clutch `i`, ω_f − ω_ci (rad/s).
    /// The series event segmentation reads ([`events::segment`]).
    pub fn segment_series(&self) -> SegmentSeries<'_> {
        SegmentSeries {
            dt: self.dt,
            torque: [self.req(Col::T1), self.req(Col::T2)],
            slip: [self.slip(0), self.slip(1)],
            pp: [self.req(Col::Pp1), self.req(Col::Pp2)],
            cd: self.req(Col::Cd),
        }
    }

    pub fn slip(&self, i: usize) -> Vec<f64> {
        let wf = self.req(Col::Wf);
        let wc = self.req(Col::wc(i));
        wf.iter().zip(wc).map(|(a, b)| a - b).collect()
    }

    /// Writes the dataset as CSV with the documented header.
    pub fn to_csv(&self) -> String {
        use std::fmt::Write as _;
        let cols = self.columns();
        let mut s = String::with_capacity(self.len() * 16 * (cols.len() + 1));
        s.push_str("time_s");
        for c in &cols {
            s.push(',');
            s.push_str(c.name());
        }
        s.push('\n');
        for k in 0..self.len() {
            let _ = write!(s, "{:.4}", self.time[k]);
            for c in &cols {
                let v = self.cols[c.idx()]
                    .as_ref()
                    .map(|v| v[k])
                    .unwrap_or(f64::NAN);
                if c.discrete() {
                    let _ = write!(s, ",{v:.0}");
                } else {
                    let _ = write!(s, ",{v:.5}");
                }
            }
            s.push('\n');
        }
        s
    }

    /// Loads a CSV or candump file, chosen by content: a candump log starts with `(`. One record:
    /// a file with gaps in time is refused ([`DatasetError::Gaps`]); [`Segments::load`] cuts it.
    pub fn load(path: impl AsRef<Path>) -> Result<Dataset, DatasetError> {
        let (file, raw) = read_file(path.as_ref())?;
        raw.single(&file)
    }

    /// Parses CSV text (comma separated, one header line, `#` comment lines allowed) into one
    /// record (see [`Segments::from_csv`] for records with gaps).
    pub fn from_csv(file: &str, text: &str) -> Result<Dataset, DatasetError> {
        parse_csv(file, text)?.single(file)
    }

    /// Decodes a candump log with the contract and resamples it at `dt` seconds (one record).
    pub fn from_candump(file: &str, input: impl BufRead, dt: f64) -> Result<Dataset, DatasetError> {
        decode_log(file, candump_lines(file, input), dt)?.single(file)
    }

    /// Decodes logged frames (e.g. straight from an in-process bus) and resamples them (one
    /// record). Errors name the frame's 1-based position as its line (the line of a log written
    /// one frame per line).
    pub fn from_records(
        file: &str,
        records: impl IntoIterator<Item = Result<LogRecord, DatasetError>>,
        dt: f64,
    ) -> Result<Dataset, DatasetError> {
        decode_log(file, numbered(records), dt)?.single(file)
    }
}

/// A gap in time that cuts a record.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct TimeGap {
    /// Line of the first sample after the gap (the CSV row; the `ENG_Status` frame of a log).
    pub line: usize,
    /// Time of the last sample before the gap (s, the file's clock).
    pub from_s: f64,
    /// Time of the first sample after it.
    pub to_s: f64,
}

/// A segment left out of the diagnosis.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct DroppedSegment {
    /// `file[segment k]`.
    pub source: String,
    /// Its first and last sample of the clock (s, the file's clock).
    pub from_s: f64,
    pub to_s: f64,
    /// Samples of the clock in it.
    pub samples: usize,
    pub reason: String,
}

/// A file cut at its gaps in time: the segments long enough for the diagnosis, each a record of
/// its own (`file[segment k]` when there are several), in time order.
#[derive(Debug, Clone, PartialEq)]
pub struct Segments {
    pub file: String,
    pub datasets: Vec<Dataset>,
    /// Where the file was cut.
    pub gaps: Vec<TimeGap>,
    /// Segments shorter than [`MIN_RECORD_S`] (or without the required signals), left out.
    pub dropped: Vec<DroppedSegment>,
}

impl Segments {
    /// Loads a CSV or candump file (chosen by content, as [`Dataset::load`]) and cuts it at its
    /// gaps in time. Errors: anything [`Dataset::load`] rejects except the gaps; a file with one
    /// segment shorter than [`MIN_RECORD_S`] ([`DatasetError::RecordTooShort`]), with no segment
    /// that long ([`DatasetError::NoUsableSegment`]) or in which no clutch ever closes
    /// ([`DatasetError::NoEngagement`]).
    pub fn load(path: impl AsRef<Path>) -> Result<Segments, DatasetError> {
        let (file, raw) = read_file(path.as_ref())?;
        Segments::build(file, raw)
    }

    /// [`Segments::load`] of CSV text.
    pub fn from_csv(file: &str, text: &str) -> Result<Segments, DatasetError> {
        Segments::build(file.into(), parse_csv(file, text)?)
    }

    /// [`Segments::load`] of a candump log, resampled at `dt` seconds.
    pub fn from_candump(
        file: &str,
        input: impl BufRead,
        dt: f64,
    ) -> Result<Segments, DatasetError> {
        Segments::build(
            file.into(),
            decode_log(file, candump_lines(file, input), dt)?,
        )
    }

    /// [`Segments::load`] of logged frames.
    pub fn from_records(
        file: &str,
        records: impl IntoIterator<Item = Result<LogRecord, DatasetError>>,
        dt: f64,
    ) -> Result<Segments, DatasetError> {
        Segments::build(file.into(), decode_log(file, numbered(records), dt)?)
    }

    fn build(file: String, raw: RawRecord) -> Result<Segments, DatasetError> {
        let (parts, gaps) = raw.split(&file);
        let single = parts.len() == 1;
        let n_parts = parts.len();
        let mut datasets = Vec::new();
        let mut dropped = Vec::new();
        let mut longest = 0.0f64;
        for p in parts {
            let reason = match p.result {
                Ok(d) if d.duration() >= MIN_RECORD_S - 1e-9 => {
                    datasets.push(d);
                    continue;
                }
                Ok(d) => {
                    longest = longest.max(d.duration());
                    if single {
                        return Err(DatasetError::RecordTooShort {
                            file,
                            duration_s: d.duration(),
                            min_s: MIN_RECORD_S,
                        });
                    }
                    format!(
                        "it lasts {} s, shorter than one engagement ({} s)",
                        num(&d.duration()),
                        num(&MIN_RECORD_S)
                    )
                }
                Err(e) if single => return Err(e),
                Err(e) => e.to_string(),
            };
            dropped.push(DroppedSegment {
                source: p.source,
                from_s: p.from_s,
                to_s: p.to_s,
                samples: p.samples,
                reason,
            });
        }
        if datasets.is_empty() {
            return Err(DatasetError::NoUsableSegment {
                file,
                segments: n_parts,
                longest_s: longest,
                min_s: MIN_RECORD_S,
            });
        }
        // One engagement: a clutch closed (above the event threshold, long enough to be an
        // event) somewhere in the file.
        let o = SegmentOptions::default();
        let engaged = datasets.iter().any(|d| {
            events::segment(&d.segment_series(), &o)
                .events
                .iter()
                .any(|e| matches!(e.kind, EventKind::Engagement | EventKind::Locked))
        });
        if !engaged {
            return Err(DatasetError::NoEngagement {
                file,
                torque_on: o.torque_on,
                min_s: o.min_engagement_s,
            });
        }
        Ok(Segments {
            file,
            datasets,
            gaps,
            dropped,
        })
    }

    /// Samples of the segments kept.
    pub fn samples(&self) -> usize {
        self.datasets.iter().map(Dataset::len).sum()
    }

    /// One line per gap and per dropped segment, for the user (empty for a plain record).
    pub fn notes(&self) -> Vec<String> {
        let mut out = Vec::new();
        if !self.gaps.is_empty() {
            let segs = self.gaps.len() + 1;
            for g in &self.gaps {
                out.push(format!(
                    "{}:{}: a gap in time of {} s ({} s → {} s): the record is cut there",
                    self.file,
                    g.line,
                    num(&(g.to_s - g.from_s)),
                    num(&g.from_s),
                    num(&g.to_s)
                ));
            }
            out.push(format!(
                "{}: {segs} segments, {} kept as separate records ({} samples)",
                self.file,
                self.datasets.len(),
                self.samples()
            ));
        }
        for d in &self.dropped {
            out.push(format!(
                "{} ({} s → {} s, {} samples) left out: {}",
                d.source,
                num(&d.from_s),
                num(&d.to_s),
                d.samples,
                d.reason
            ));
        }
        out
    }
}

/// Reads a file and parses it as an MDF 4 bus log (it starts with `MDF `), CSV or candump (a
/// log starts with `(`).
fn read_file(path: &Path) -> Result<(String, RawRecord), DatasetError> {
    let file = path.display().to_string();
    let bytes = std::fs::read(path).map_err(|e| DatasetError::Io {
        file: file.clone(),
        source: e.into(),
    })?;
    if crate::can::mf4::is_mdf(&bytes) {
        let mdf = |source| DatasetError::Mf4 {
            file: file.clone(),
            source,
        };
        let frames = crate::can::mf4::read(&bytes).map_err(mdf)?;
        let raw = decode_log(
            &file,
            numbered(frames.map(|r| r.map_err(mdf))),
            DEFAULT_DT_S,
        )?;
        return Ok((file, raw));
    }
    let text = String::from_utf8(bytes).map_err(|e| DatasetError::Io {
        file: file.clone(),
        source: std::io::Error::new(std::io::ErrorKind::InvalidData, e).into(),
    })?;
    let raw = if text.trim_start().starts_with('(') {
        decode_log(&file, candump_text(&file, &text), DEFAULT_DT_S)?
    } else {
        parse_csv(&file, &text)?
    };
    Ok((file, raw))
}

/// Parses CSV text: the header, every value checked (finite, inside its physical range, gears
/// in the DBC table), the time column increasing by at least [`MIN_STEP_S`].
///
/// The fields are read by the `csv` crate (quoted fields allowed), trimmed. A line that is blank
/// or whose first character that is not white space is `#` is a comment ([`blank_comments`]:
/// `csv` takes a comment only at the very start of a line, a line of spaces for a record, and
/// counts lines past the empty ones it skips in its own way); an error names the file's line.
fn parse_csv(file: &str, text: &str) -> Result<RawRecord, DatasetError> {
    let kept = blank_comments(text);
    // A record's line from its byte offset.
    let ends: Vec<usize> = memchr::memchr_iter(b'\n', kept.as_bytes()).collect();
    let line_at = |p: Option<&csv::Position>| {
        p.map_or(0, |p| ends.partition_point(|&e| (e as u64) < p.byte()) + 1)
    };
    let mut reader = csv::ReaderBuilder::new()
        .has_headers(false)
        .flexible(true)
        .trim(csv::Trim::All)
        .from_reader(kept.as_bytes());
    let mut records = reader
        .records()
        .filter(|r| !r.as_ref().is_ok_and(is_comment))
        .map(|r| {
            r.map(|r| (line_at(r.position()), r))
                .map_err(|e| DatasetError::Csv {
                    file: file.into(),
                    line: line_at(e.position()),
                    source: std::io::Error::from(e).into(),
                })
        });
    let Some(first) = records.next() else {
        return Err(DatasetError::Empty { file: file.into() });
    };
    let (hline, header) = first?;
    let mut columns = csv_columns(file, hline, &header)?;
    let mut stats = LoadStats {
        ignored_columns: std::mem::take(&mut columns.ignored),
        ..LoadStats::default()
    };
    let mut t = Vec::new();
    let mut row_lines = Vec::new();
    let mut cols: Vec<Vec<f64>> = vec![Vec::new(); NCOL];
    for r in records {
        let (line, fields) = r?;
        csv_row(file, line, &fields, &columns, &mut t, &mut cols)?;
        row_lines.push(line);
        stats.records += 1;
    }
    if t.len() < 2 {
        return Err(DatasetError::TooShort {
            file: file.into(),
            rows: t.len(),
            min: 2,
        });
    }
    let dt = median_step(&t);
    let hold = (dt * 5.5).max(MAX_HOLD_S);
    Ok(RawRecord {
        cols: Col::ALL
            .iter()
            .map(|c| columns.seen[c.idx()].then(|| (0, std::mem::take(&mut cols[c.idx()]))))
            .collect(),
        times: vec![t],
        clock: 0,
        clock_lines: row_lines,
        dt,
        hold,
        cycles: false,
        stats,
    })
}

/// A CSV header's columns.
struct CsvColumns {
    /// Number of fields.
    len: usize,
    /// The known column of each field (`None` for the time and the ignored ones).
    map: Vec<Option<Col>>,
    /// The time column's field.
    time: usize,
    /// The known columns present.
    seen: [bool; NCOL],
    /// Names of the unknown fields, ignored.
    ignored: Vec<String>,
}

/// The header's column map: each field's column, the time column, the unknown ones; an error
/// for a column named twice or a required one missing.
fn csv_columns(
    file: &str,
    hline: usize,
    header: &csv::StringRecord,
) -> Result<CsvColumns, DatasetError> {
    let names: Vec<&str> = header.iter().collect();
    let mut map: Vec<Option<Col>> = Vec::with_capacity(names.len());
    let mut time_idx = None;
    let mut seen = [false; NCOL];
    let mut ignored = Vec::new();
    let duplicate = |j: usize, name: &str| DatasetError::DuplicateColumn {
        file: file.into(),
        line: hline,
        index: j + 1,
        column: name.to_string(),
    };
    for (j, name) in names.iter().enumerate() {
        if *name == "time_s" {
            if time_idx.is_some() {
                return Err(duplicate(j, name));
            }
            time_idx = Some(j);
            map.push(None);
            continue;
        }
        match Col::from_name(name) {
            Some(c) => {
                if seen[c.idx()] {
                    return Err(duplicate(j, name));
                }
                seen[c.idx()] = true;
                map.push(Some(c));
            }
            None => {
                ignored.push(name.to_string());
                map.push(None);
            }
        }
    }
    let missing = |column: &str| DatasetError::MissingColumn {
        file: file.into(),
        line: hline,
        column: column.into(),
    };
    let Some(time) = time_idx else {
        return Err(missing("time_s"));
    };
    if let Some(c) = Col::ALL.iter().find(|c| c.required() && !seen[c.idx()]) {
        return Err(missing(c.name()));
    }
    Ok(CsvColumns {
        len: names.len(),
        map,
        time,
        seen,
        ignored,
    })
}

/// One row's fields: each number parsed and checked, the time appended to `t`, every known
/// column's value to its column of `cols`; an error for a wrong field count or a bad value.
fn csv_row(
    file: &str,
    line: usize,
    fields: &csv::StringRecord,
    columns: &CsvColumns,
    t: &mut Vec<f64>,
    cols: &mut [Vec<f64>],
) -> Result<(), DatasetError> {
    if fields.len() != columns.len {
        return Err(DatasetError::FieldCount {
            file: file.into(),
            line,
            expected: columns.len,
            found: fields.len(),
        });
    }
    for (j, f) in fields.iter().enumerate() {
        let column = match columns.map[j] {
            Some(c) => c.name(),
            None if j == columns.time => "time_s",
            None => continue,
        };
        let v = parse_num(f).ok_or_else(|| DatasetError::BadNumber {
            file: file.into(),
            line,
            index: j + 1,
            column: column.into(),
            text: f.to_string(),
        })?;
        let Some(c) = columns.map[j] else {
            check_time(file, line, j + 1, v, t.last().copied())?;
            t.push(v);
            continue;
        };
        c.check(v).map_err(|e| e.at(file, line, j + 1, c, v))?;
        cols[c.idx()].push(v);
    }
    Ok(())
}

/// The time column's checks: a time `v` (field `index` of `line`) is not before the `previous`
/// one and at least [`MIN_STEP_S`] after it.
fn check_time(
    file: &str,
    line: usize,
    index: usize,
    v: f64,
    previous: Option<f64>,
) -> Result<(), DatasetError> {
    let Some(previous) = previous else {
        return Ok(());
    };
    if v < previous {
        return Err(DatasetError::TimeOrder {
            file: file.into(),
            line,
            index,
            value: v,
            previous,
        });
    }
    // Relative tolerance: a 0.1 ms step written with 4 decimals still passes.
    if v - previous < MIN_STEP_S * (1.0 - 1e-6) {
        return Err(DatasetError::TimeStep {
            file: file.into(),
            line,
            index,
            value: v,
            previous,
        });
    }
    Ok(())
}

/// The step a CSV record keeps: the file's own step when it is uniform, else its median step to
/// resample at (every step is at least [`MIN_STEP_S`], so is the median).
fn median_step(t: &[f64]) -> f64 {
    let mut steps: Vec<f64> = t.windows(2).map(|w| w[1] - w[0]).collect();
    steps.sort_by(f64::total_cmp);
    steps[steps.len() / 2]
}

/// `text` for the CSV reader: line ends as `\n`, each comment or blank line replaced by `#`, a
/// record [`parse_csv`] drops ([`is_comment`]). No line is empty, so the reader skips none and a
/// record's byte offset gives its line.
fn blank_comments(text: &str) -> String {
    let mut out = String::with_capacity(text.len() + 2);
    for l in text.lines() {
        let t = l.trim();
        out.push_str(if t.is_empty() || t.starts_with('#') {
            "#"
        } else {
            l
        });
        out.push('\n');
    }
    out
}

/// Whether a record is one [`blank_comments`] put in place of a comment or blank line.
fn is_comment(r: &csv::StringRecord) -> bool {
    r.len() == 1 && &r[0] == "#"
}

fn parse_num(s: &str) -> Option<f64> {
    s.parse::<f64>().ok().filter(|v| v.is_finite())
}

/// The lines of a candump log, numbered as in the file (blank lines skipped).
fn candump_lines<'a>(
    file: &'a str,
    input: impl BufRead + 'a,
) -> impl Iterator<Item = Result<Stamped, DatasetError>> + 'a {
    input
        .lines()
        .enumerate()
        .filter(|(_, l)| l.as_ref().map_or(true, |l| !l.trim().is_empty()))
        .map(move |(i, l)| {
            let line = i + 1;
            let l = l.map_err(|e| {
                if e.kind() == std::io::ErrorKind::InvalidData {
                    DatasetError::LogLine {
                        file: file.into(),
                        line,
                        source: LineError::Timestamp,
                    }
                } else {
                    DatasetError::Io {
                        file: file.into(),
                        source: e.into(),
                    }
                }
            })?;
            candump_line(file, line, &l)
        })
}

/// [`candump_lines`] of a log already in memory: each line borrowed from `text`, not copied
/// into a string of its own (`str::lines` ends lines where `BufRead::lines` does, at `\n` with
/// an optional `\r` before it), and a line in the form candump writes parsed in place
/// ([`parse_canonical`], which gives what [`parse_line`] gives wherever it accepts a line).
fn candump_text<'a>(
    file: &'a str,
    text: &'a str,
) -> impl Iterator<Item = Result<Stamped, DatasetError>> + 'a {
    text.lines()
        .enumerate()
        .filter(|(_, l)| !l.trim().is_empty())
        .map(move |(i, l)| match parse_canonical(l.as_bytes()) {
            Some(r) => Ok(Stamped {
                line: i + 1,
                timestamp: r.timestamp,
                frame: r.frame,
            }),
            None => candump_line(file, i + 1, l),
        })
}

/// One candump line, numbered `line`, parsed; an error names the file and the line.
fn candump_line(file: &str, line: usize, l: &str) -> Result<Stamped, DatasetError> {
    parse_line(l)
        .map(|r| Stamped::of(line, &r))
        .map_err(|kind| DatasetError::LogLine {
            file: file.into(),
            line,
            source: kind,
        })
}

/// In-memory frames numbered from 1.
fn numbered(
    records: impl IntoIterator<Item = Result<LogRecord, DatasetError>>,
) -> impl Iterator<Item = Result<Stamped, DatasetError>> {
    records
        .into_iter()
        .enumerate()
        .map(|(i, r)| r.map(|r| Stamped::of(i + 1, &r)))
}

/// What the decoding reads of a logged frame: its line (or position) and time, and the frame.
#[derive(Debug, Clone, Copy)]
struct Stamped {
    line: usize,
    timestamp: std::time::Duration,
    frame: crate::can::CanFrame,
}

impl Stamped {
    fn of(line: usize, r: &LogRecord) -> Self {
        Stamped {
            line,
            timestamp: r.timestamp,
            frame: r.frame,
        }
    }
}

/// The messages whose signals become columns: a decoding failure of one of them (a value outside
/// the DBC range or value table) is an impossible value, not a frame to skip.
fn read_here(id: u32) -> bool {
    [
        ids::ENG_STATUS,
        ids::DCT_SENSORS,
        ids::DCT_ACTUATORS,
        ids::BENCH_TORQUE,
        ids::BENCH_TEMPS,
        ids::TCU_CLUTCH_CMD,
        ids::DRV_PEDAL,
    ]
    .into_iter()
    .any(|m| u32::from(m) == id)
}

/// Decodes numbered frames with the contract into per-signal series.
fn decode_log(
    file: &str,
    records: impl Iterator<Item = Result<Stamped, DatasetError>>,
    dt: f64,
) -> Result<RawRecord, DatasetError> {
    let mut raw = CandumpColumns::default();
    let mut stats = LoadStats::default();
    let mut checker: Option<E2eChecker> = None;
    let mut t0: Option<std::time::Duration> = None;
    let mut latest = 0.0f64;
    for rec in records {
        let rec = rec?;
        let line = rec.line;
        stats.records += 1;
        let frame = &rec.frame;
        if frame.is_extended() || frame.is_remote_frame() {
            stats.undecodable += 1;
            continue;
        }
        let id = frame.raw_id();
        if id == u32::from(ids::SIM_TRUTH) {
            stats.ignored_truth += 1;
            continue;
        }
        let start = *t0.get_or_insert(rec.timestamp);
        let t = seconds_since(start, rec.timestamp);
        if t < latest - MAX_HOLD_S {
            return Err(DatasetError::LogTimeOrder {
                file: file.into(),
                line,
                value: t,
                previous: latest,
            });
        }
        latest = latest.max(t);
        if is_protected(id) {
            let ch = checker.get_or_insert_with(|| E2eChecker::all(E2eConfig::default(), start));
            match ch.check(rec.timestamp, id, frame.bytes()) {
                Ok(()) | Err(E2eError::CounterSkipped { .. }) => {}
                Err(_) => {
                    stats.dropped_e2e += 1;
                    continue;
                }
            }
        }
        let msg = match Message::decode(id, frame.bytes()) {
            Ok(m) => m,
            Err(e) => match signal_error(file, line, id, e) {
                Some(e) => return Err(e),
                None => {
                    stats.undecodable += 1;
                    continue;
                }
            },
        };
        raw.push(t, line, &msg);
    }
    raw.into_raw(file, dt, stats)
}

/// Signed seconds from `start` to `timestamp` (a frame older than the first is reordering too).
fn seconds_since(start: std::time::Duration, timestamp: std::time::Duration) -> f64 {
    match timestamp.checked_sub(start) {
        Some(d) => d.as_secs_f64(),
        None => -(start - timestamp).as_secs_f64(),
    }
}

/// The error of a frame of message `id` (at `line`) that does not decode: a signal out of its
/// range or without an entry in its value table, in a message the diagnosis reads; `None` for
/// the others, which are only counted as undecodable.
fn signal_error(file: &str, line: usize, id: u32, e: CodecError) -> Option<DatasetError> {
    if !read_here(id) {
        return None;
    }
    let def =
        |signal: &str| message_def(id).and_then(|d| d.signals.iter().find(|s| s.name == signal));
    match e {
        CodecError::OutOfRange {
            message,
            signal,
            value,
            min,
            max,
        } => {
            let unit = def(signal).map_or("", |s| s.unit);
            Some(DatasetError::SignalRange {
                file: file.into(),
                line,
                signal: format!("{message}.{signal}"),
                value,
                min,
                max,
                unit: unit.into(),
            })
        }
        CodecError::UnknownValue {
            message,
            signal,
            raw: r,
        } => {
            let table = def(signal).map_or_else(String::new, value_table);
            Some(DatasetError::SignalValue {
                file: file.into(),
                line,
                signal: format!("{message}.{signal}"),
                raw: r,
                table,
            })
        }
        _ => None,
    }
}

/// One signal's samples at its own times.
#[derive(Debug, Clone, Default)]
struct Series {
    t: Vec<f64>,
    v: Vec<f64>,
}

impl Series {
    /// Appends a sample; false (and nothing kept) for one not newer than the last.
    fn push(&mut self, t: f64, v: f64) -> bool {
        // Logs are in time order; a frame with an older timestamp (reordering) is ignored.
        if self.t.last().is_none_or(|&last| t > last) {
            self.t.push(t);
            self.v.push(v);
            true
        } else {
            false
        }
    }
}

/// A borrowed piece of a series.
#[derive(Debug, Clone, Copy)]
struct SeriesRef<'a> {
    t: &'a [f64],
    v: &'a [f64],
}

/// A bench measurement sitting at its DBC range limit is clipped, not measured: NaN (the grid
/// points around it become invalid).
fn unsaturated(s: &SignalDef, v: f64) -> f64 {
    let half = 0.5 * s.factor.abs();
    if v >= s.max - half || v <= s.min + half {
        f64::NAN
    } else {
        v
    }
}

#[derive(Debug, Default)]
struct CandumpColumns {
    s: Vec<Series>,
    /// Line of each `ENG_Status` sample kept (the clock).
    clock_lines: Vec<usize>,
}

impl CandumpColumns {
    fn col(&mut self, c: Col) -> &mut Series {
        if self.s.is_empty() {
            self.s = vec![Series::default(); NCOL];
        }
        &mut self.s[c.idx()]
    }

    fn push(&mut self, t: f64, line: usize, m: &Message) {
        match m {
            Message::EngStatus(e) => {
                if self.col(Col::Wf).push(t, e.eng_speed * RPM_TO_RADPS) {
                    self.clock_lines.push(line);
                }
                self.col(Col::Te).push(t, e.eng_torque_act);
            }
            Message::DctSensors(d) => {
                self.col(Col::Wc1).push(t, d.in_shaft1_speed * RPM_TO_RADPS);
                self.col(Col::Wc2).push(t, d.in_shaft2_speed * RPM_TO_RADPS);
                self.col(Col::Wout)
                    .push(t, d.out_shaft_speed * RPM_TO_RADPS);
                self.col(Col::Th).push(t, d.housing_temp);
            }
            Message::DctActuators(a) => {
                self.col(Col::X1).push(t, a.clutch1_pos);
                self.col(Col::X2).push(t, a.clutch2_pos);
                self.col(Col::GearOdd)
                    .push(t, f64::from(Gear::from(a.gear_odd_act).code()));
                self.col(Col::GearEven)
                    .push(t, f64::from(Gear::from(a.gear_even_act).code()));
            }
            Message::BenchTorque(b) => {
                use crate::can::messages::BenchTorque as B;
                self.col(Col::T1)
                    .push(t, unsaturated(B::clutch1_torque_def(), b.clutch1_torque));
                self.col(Col::T2)
                    .push(t, unsaturated(B::clutch2_torque_def(), b.clutch2_torque));
            }
            Message::BenchTemps(b) => {
                use crate::can::messages::BenchTemps as B;
                self.col(Col::Pp1).push(
                    t,
                    unsaturated(B::pressure_plate1_temp_def(), b.pressure_plate1_temp),
                );
                self.col(Col::Pp2).push(
                    t,
                    unsaturated(B::pressure_plate2_temp_def(), b.pressure_plate2_temp),
                );
                self.col(Col::Cd).push(
                    t,
                    unsaturated(B::central_disk_temp_def(), b.central_disk_temp),
                );
            }
            Message::TcuClutchCmd(c) => {
                self.col(Col::X1Req).push(t, c.clutch1_pos_req);
                self.col(Col::X2Req).push(t, c.clutch2_pos_req);
            }
            Message::DrvPedal(p) => {
                self.col(Col::Pedal).push(t, p.accel_pedal);
            }
            // Everything else (TCU status/estimates, vehicle, engine requests) is not a column;
            // SIM_Truth never reaches this point.
            _ => {}
        }
    }

    fn into_raw(
        mut self,
        file: &str,
        dt: f64,
        stats: LoadStats,
    ) -> Result<RawRecord, DatasetError> {
        if self.s.is_empty() {
            self.s = vec![Series::default(); NCOL];
        }
        // Required messages, named by the message that carries them.
        let needs: [(&'static str, &[Col]); 5] = [
            (
                crate::can::messages::DctActuators::NAME,
                &[Col::X1, Col::X2],
            ),
            (crate::can::messages::EngStatus::NAME, &[Col::Wf]),
            (
                crate::can::messages::DctSensors::NAME,
                &[Col::Wc1, Col::Wc2, Col::Th],
            ),
            (crate::can::messages::BenchTorque::NAME, &[Col::T1, Col::T2]),
            (
                crate::can::messages::BenchTemps::NAME,
                &[Col::Pp1, Col::Pp2, Col::Cd],
            ),
        ];
        for (msg, cols) in needs {
            if cols.iter().any(|c| self.s[c.idx()].t.len() < 2) {
                return Err(DatasetError::MissingMessage {
                    file: file.into(),
                    message: msg,
                    columns: cols.iter().map(|c| c.name()).collect::<Vec<_>>().join(", "),
                });
            }
        }
        let mut times = Vec::new();
        let mut cols = Vec::with_capacity(NCOL);
        for s in self.s {
            if s.t.len() >= 2 {
                cols.push(Some((times.len(), s.v)));
                times.push(s.t);
            } else {
                cols.push(None);
            }
        }
        let clock = cols[Col::Wf.idx()]
            .as_ref()
            .map(|(k, _)| *k)
            .expect("ENG_Status present");
        Ok(RawRecord {
            times,
            cols,
            clock,
            clock_lines: self.clock_lines,
            dt,
            hold: MAX_HOLD_S,
            cycles: true,
            stats,
        })
    }
}

/// A record as read, before resampling: every present column's samples at their own times.
struct RawRecord {
    /// Sample times (CSV: one vector for every column; candump: one per column).
    times: Vec<Vec<f64>>,
    /// Per column: its index in `times` and its values.
    cols: Vec<Option<(usize, Vec<f64>)>>,
    /// The clock whose gaps cut the record (index in `times`): CSV rows, ENG_Status frames.
    clock: usize,
    /// File line of each clock sample.
    clock_lines: Vec<usize>,
    dt: f64,
    /// Longest interval interpolated over; a longer one in the clock is a gap.
    hold: f64,
    /// Bus log: the grid follows the plant's cycles (see [`resample`]).
    cycles: bool,
    stats: LoadStats,
}

/// One segment of a record, resampled (or why it could not be).
struct Part {
    source: String,
    from_s: f64,
    to_s: f64,
    samples: usize,
    result: Result<Dataset, DatasetError>,
}

impl RawRecord {
    /// Cuts the record where consecutive clock samples are more than `hold` apart (at the middle
    /// of each gap, so every sample lands in one segment) and resamples each segment on its own:
    /// nothing is filled across a gap.
    fn split(&self, file: &str) -> (Vec<Part>, Vec<TimeGap>) {
        let clock = &self.times[self.clock];
        let gaps: Vec<TimeGap> = (1..clock.len())
            .filter(|&k| clock[k] - clock[k - 1] > self.hold)
            .map(|k| TimeGap {
                line: self.clock_lines.get(k).copied().unwrap_or(0),
                from_s: clock[k - 1],
                to_s: clock[k],
            })
            .collect();
        let mut cuts = vec![f64::NEG_INFINITY];
        cuts.extend(gaps.iter().map(|g| 0.5 * (g.from_s + g.to_s)));
        cuts.push(f64::INFINITY);
        let parts = cuts
            .windows(2)
            .enumerate()
            .map(|(i, w)| {
                let range = |t: &[f64]| {
                    t.partition_point(|&x| x <= w[0])..t.partition_point(|&x| x <= w[1])
                };
                let series: Vec<Option<SeriesRef>> = self
                    .cols
                    .iter()
                    .map(|c| {
                        c.as_ref().map(|(ti, v)| {
                            let t = &self.times[*ti];
                            let r = range(t);
                            SeriesRef {
                                t: &t[r.clone()],
                                v: &v[r],
                            }
                        })
                    })
                    .collect();
                let source = if gaps.is_empty() {
                    file.to_string()
                } else {
                    format!("{file}[segment {}]", i + 1)
                };
                let c = &clock[range(clock)];
                let mut stats = self.stats.clone();
                if !self.cycles {
                    stats.records = c.len();
                }
                Part {
                    from_s: c.first().copied().unwrap_or(f64::NAN),
                    to_s: c.last().copied().unwrap_or(f64::NAN),
                    samples: c.len(),
                    result: resample(&source, &series, self.dt, self.hold, stats, self.cycles),
                    source,
                }
            })
            .collect();
        (parts, gaps)
    }

    /// The record as one dataset; an error if gaps cut it.
    fn single(&self, file: &str) -> Result<Dataset, DatasetError> {
        let (mut parts, gaps) = self.split(file);
        if parts.len() == 1 {
            return parts.pop().expect("one part").result;
        }
        Err(DatasetError::Gaps {
            file: file.into(),
            line: gaps[0].line,
            from_s: gaps[0].from_s,
            to_s: gaps[0].to_s,
            segments: parts.len(),
        })
    }
}

/// A grid point closer to a sample than this share of the step between samples is on it.
const ON_SAMPLE: f64 = 1e-6;

/// Resamples every present series onto a uniform grid over the common span of the required ones.
///
/// `cycles` (bus logs): the grid is anchored at the plant's cycle clock (ENG_Status times) and a
/// sensor value at a grid point is the sample of the same cycle (the nearest within half a step;
/// linear interpolation only across a missing cycle), so frames sent a few microseconds apart
/// within one cycle are one sample; commands use zero-order hold. Otherwise (CSV rows) values
/// are interpolated linearly.
fn resample(
    file: &str,
    series: &[Option<SeriesRef>],
    dt: f64,
    hold: f64,
    mut stats: LoadStats,
    cycles: bool,
) -> Result<Dataset, DatasetError> {
    let (t_start, t_end) = grid_span(file, series, dt, cycles)?;
    let n = ((t_end - t_start) / dt + 1e-9).floor() as usize + 1;
    if n < 2 {
        return Err(DatasetError::TooShort {
            file: file.into(),
            rows: n,
            min: 2,
        });
    }
    let grid: Vec<f64> = (0..n).map(|k| t_start + k as f64 * dt).collect();
    let mut valid = vec![true; n];
    let mut cols: Vec<Option<Vec<f64>>> = vec![None; NCOL];
    for c in Col::ALL {
        let Some(s) = series[c.idx()].as_ref() else {
            continue;
        };
        if s.t.is_empty() {
            // An optional signal silent in this segment: absent here.
            continue;
        }
        cols[c.idx()] = Some(on_grid(c, s, &grid, dt, hold, cycles, &mut valid));
    }
    stats.invalid_points = valid.iter().filter(|v| !**v).count();
    Ok(Dataset {
        source: file.into(),
        time: grid.iter().map(|t| t - t_start).collect(),
        dt,
        cols,
        valid,
        stats,
        start_s: t_start,
    })
}

/// The grid's span: the common span of the required series (with `cycles`, anchored at the
/// cycle clock's first time in it and extended by half a step); an error when a required series
/// is too short or the span is empty.
fn grid_span(
    file: &str,
    series: &[Option<SeriesRef>],
    dt: f64,
    cycles: bool,
) -> Result<(f64, f64), DatasetError> {
    let mut t_start = f64::NEG_INFINITY;
    let mut t_end = f64::INFINITY;
    for c in Col::ALL.iter().filter(|c| c.required()) {
        let s = series[c.idx()].as_ref().expect("required series present");
        if s.t.len() < 2 && !cycles {
            return Err(DatasetError::TooShort {
                file: file.into(),
                rows: s.t.len(),
                min: 2,
            });
        }
        let (Some(&first), Some(&last)) = (s.t.first(), s.t.last()) else {
            return Err(DatasetError::NoOverlap { file: file.into() });
        };
        t_start = t_start.max(first);
        t_end = t_end.min(last);
    }
    if cycles {
        let clock = series[Col::Wf.idx()]
            .as_ref()
            .expect("required series present")
            .t;
        let half = 0.5 * dt;
        if let Some(&a) = clock.iter().find(|&&t| t >= t_start - half) {
            t_start = a;
        }
        t_end += half;
    }
    if t_end.partial_cmp(&t_start) != Some(std::cmp::Ordering::Greater) {
        return Err(DatasetError::NoOverlap { file: file.into() });
    }
    Ok((t_start, t_end))
}

/// Column `c`'s series `s` (not empty) on the grid, as [`resample`] describes; a grid point
/// where a required column has no fresh finite value is marked invalid in `valid`.
fn on_grid(
    c: Col,
    s: &SeriesRef,
    grid: &[f64],
    dt: f64,
    hold: f64,
    cycles: bool,
    valid: &mut [bool],
) -> Vec<f64> {
    let mut out = Vec::with_capacity(grid.len());
    let mut j = 0usize;
    for (k, &t) in grid.iter().enumerate() {
        while j + 1 < s.t.len() && s.t[j + 1] <= t {
            j += 1;
        }
        // s.t[j] <= t < s.t[j+1] (or t before the first / after the last sample).
        let nearest = cycles && !c.command() && !c.discrete();
        let (v, fresh) = if nearest && {
            let d0 = (s.t[j] - t).abs();
            let d1 = s.t.get(j + 1).map_or(f64::INFINITY, |&tb| (tb - t).abs());
            d0.min(d1) <= 0.5 * dt
        } {
            // The sample of this cycle.
            let d0 = (s.t[j] - t).abs();
            let d1 = s.t.get(j + 1).map_or(f64::INFINITY, |&tb| (tb - t).abs());
            (if d1 < d0 { s.v[j + 1] } else { s.v[j] }, true)
        } else if t < s.t[0] {
            (s.v[0], s.t[0] - t <= hold)
        } else if j + 1 >= s.t.len() || c.discrete() || (cycles && c.command()) {
            let next = s.t.get(j + 1).copied().unwrap_or(f64::INFINITY);
            (s.v[j], next - s.t[j] <= hold || t - s.t[j] <= hold)
        } else {
            let (ta, tb) = (s.t[j], s.t[j + 1]);
            let w = (t - ta) / (tb - ta);
            // A grid point on a sample (to the rounding of the times) is that sample as logged,
            // not an interpolation a rounding away from it: a held or quantised channel keeps
            // its equal readings and its grid.
            let v = if w <= ON_SAMPLE {
                s.v[j]
            } else if w >= 1.0 - ON_SAMPLE {
                s.v[j + 1]
            } else {
                s.v[j] + (s.v[j + 1] - s.v[j]) * w
            };
            (v, tb - ta <= hold)
        };
        if (!fresh || !v.is_finite()) && c.required() {
            valid[k] = false;
        }
        // A clipped (NaN) sample holds the last finite value of the column.
        let v = if v.is_finite() {
            v
        } else {
            out.last().copied().unwrap_or(0.0)
        };
        out.push(v);
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    const HEADER: &str = "time_s,x_to1_mm,x_to2_mm,w_f_radps,w_c1_radps,w_c2_radps,T_c1_Nm,T_c2_Nm,th_pp1_C,th_pp2_C,th_cd_C,th_h_C";

    #[test]
    fn csv_round_trip_and_optional_columns() {
        let text = format!(
            "{HEADER},pedal_pct,extra\n0.00,4,0,100,0,0,1,0,25,25,25,25,0,9\n0.01,4.1,0,100,0,0,2,0,25,25,25,25,5,9\n0.02,4.2,0,100,0,0,3,0,25.1,25,25,25,10,9\n"
        );
        let d = Dataset::from_csv("a.csv", &text).unwrap();
        assert_eq!(d.len(), 3);
        assert!((d.dt - 0.01).abs() < 1e-12);
        assert_eq!(d.req(Col::T1), &[1.0, 2.0, 3.0]);
        assert_eq!(d.get(Col::Pedal).unwrap(), &[0.0, 5.0, 10.0]);
        assert!(d.get(Col::Te).is_none());
        assert_eq!(d.stats.ignored_columns, vec!["extra".to_string()]);
        let back = Dataset::from_csv("b.csv", &d.to_csv()).unwrap();
        assert_eq!(back.req(Col::X1), d.req(Col::X1));
        assert_eq!(back.get(Col::Pedal), d.get(Col::Pedal));
    }

    #[test]
    fn csv_errors_name_file_line_column() {
        let e = Dataset::from_csv("a.csv", "time_s,x_to1_mm\n0,1\n").unwrap_err();
        assert!(
            matches!(&e, DatasetError::MissingColumn { file, line: 1, column } if file == "a.csv" && column == "x_to2_mm")
        );
        let text =
            format!("{HEADER}\n0,4,0,100,0,0,1,0,25,25,25,25\n0.01,4,0,abc,0,0,1,0,25,25,25,25\n");
        let e = Dataset::from_csv("b.csv", &text).unwrap_err();
        assert_eq!(
            e,
            DatasetError::BadNumber {
                file: "b.csv".into(),
                line: 3,
                index: 4,
                column: "w_f_radps".into(),
                text: "abc".into()
            }
        );
        assert!(e.to_string().starts_with("b.csv:3: column 4 `w_f_radps`"));
        let text = format!("{HEADER}\n0,4,0,100,0,0,1,0,25,25,25,25\n0.01,4,0,100,0,0,1,0,25,25\n");
        assert!(matches!(
            Dataset::from_csv("c.csv", &text).unwrap_err(),
            DatasetError::FieldCount {
                line: 3,
                expected: 12,
                found: 10,
                ..
            }
        ));
        let text = format!(
            "{HEADER}\n0.01,4,0,100,0,0,1,0,25,25,25,25\n0.01,4,0,100,0,0,1,0,25,25,25,25\n"
        );
        assert!(matches!(
            Dataset::from_csv("d.csv", &text).unwrap_err(),
            DatasetError::TimeStep {
                line: 3,
                index: 1,
                ..
            }
        ));
        let text = format!("{HEADER}\n0,4,0,100,0,0,NaN,0,25,25,25,25\n");
        assert!(matches!(
            Dataset::from_csv("e.csv", &text).unwrap_err(),
            DatasetError::BadNumber {
                line: 2,
                index: 7,
                ..
            }
        ));
        assert!(matches!(
            Dataset::from_csv("f.csv", "").unwrap_err(),
            DatasetError::Empty { .. }
        ));
        let text = format!("{HEADER},T_c1_Nm\n");
        assert!(matches!(
            Dataset::from_csv("g.csv", &text).unwrap_err(),
            DatasetError::DuplicateColumn { index: 13, .. }
        ));
    }

    /// Comment lines (indented ones too), blank lines and CRLF line ends are skipped without
    /// moving the line numbers errors name; a quoted field is read as its contents.
    #[test]
    fn csv_comments_blanks_and_quotes() {
        let text = format!(
            "# rig 3\r\n{HEADER}\r\n   \r\n  # warm-up\r\n0,4,0,\"100\",0,0,1,0,25,25,25,25\r\n\r\n0.01,4,0,abc,0,0,1,0,25,25,25,25\r\n"
        );
        assert_eq!(
            Dataset::from_csv("q.csv", &text).unwrap_err(),
            DatasetError::BadNumber {
                file: "q.csv".into(),
                line: 7,
                index: 4,
                column: "w_f_radps".into(),
                text: "abc".into()
            }
        );
        let d = Dataset::from_csv("q.csv", &text.replace("abc", "100")).unwrap();
        assert_eq!(d.req(Col::Wf)[0], 100.0);
        assert_eq!(d.req(Col::Wf)[1], 100.0);
    }

    #[test]
    fn nonuniform_csv_is_resampled_linearly() {
        let text = format!(
            "{HEADER}\n0.0,4,0,100,0,0,0,0,25,25,25,25\n0.01,4,0,100,0,0,10,0,25,25,25,25\n0.03,4,0,100,0,0,30,0,25,25,25,25\n0.04,4,0,100,0,0,40,0,25,25,25,25\n"
        );
        let d = Dataset::from_csv("a.csv", &text).unwrap();
        assert_eq!(d.len(), 5);
        for (k, v) in d.req(Col::T1).iter().enumerate() {
            assert!((v - 10.0 * k as f64).abs() < 1e-9);
        }
    }

    /// A row of the required columns: clutch 1 closes (20 N·m, slipping) between 1 and 2 s of
    /// each 4 s, temperatures at 25 °C.
    fn row(t: f64) -> String {
        let tq = if (1.0..2.0).contains(&t.rem_euclid(4.0)) {
            20.0
        } else {
            0.0
        };
        format!("{t:.6},4,0,100,0,0,{tq},0,25,25,25,25\n")
    }

    fn csv(times: impl IntoIterator<Item = f64>) -> String {
        let mut s = format!("{HEADER}\n");
        for t in times {
            s.push_str(&row(t));
        }
        s
    }

    #[test]
    fn impossible_values_name_file_line_column_and_value() {
        let base = "0,4,0,100,0,0,1,0,25,25,25,25";
        let with = |extra_header: &str, bad: &str| {
            format!("{HEADER}{extra_header}\n{base}{}\n{bad}\n", {
                let n = extra_header.matches(',').count();
                ",0".repeat(n)
            })
        };
        let e = Dataset::from_csv("run.csv", &with("", "0.01,4,0,100,0,0,1,0,812,25,25,25"))
            .unwrap_err();
        assert_eq!(
            e.to_string(),
            "run.csv:3: column 9 `th_pp1_C`: 812 °C is outside the physical range \u{2212}60…600 °C"
        );
        assert!(matches!(
            e,
            DatasetError::OutOfRange { line: 3, index: 9, value, .. } if value == 812.0
        ));
        let e = Dataset::from_csv("run.csv", &with("", "0.01,4,0,100,0,0,1,0,25,25,25,-61"))
            .unwrap_err();
        assert!(
            matches!(&e, DatasetError::OutOfRange { index: 12, column, .. } if column == "th_h_C"),
            "{e}"
        );
        for c in ["th_pp2_C", "th_cd_C"] {
            let j = HEADER.split(',').position(|h| h == c).unwrap();
            let mut f: Vec<&str> = "0.01,4,0,100,0,0,1,0,25,25,25,25".split(',').collect();
            f[j] = "600.5";
            let e = Dataset::from_csv("run.csv", &with("", &f.join(","))).unwrap_err();
            assert!(
                matches!(&e, DatasetError::OutOfRange { column, line: 3, .. } if column == c),
                "{e}"
            );
        }
        let e = Dataset::from_csv(
            "run.csv",
            &with(",pedal_pct", "0.01,4,0,100,0,0,1,0,25,25,25,25,100.5"),
        )
        .unwrap_err();
        assert_eq!(
            e.to_string(),
            "run.csv:3: column 13 `pedal_pct`: 100.5 % is outside the physical range 0…100 %"
        );
        let e = Dataset::from_csv(
            "run.csv",
            &with(",gear_odd", "0.01,4,0,100,0,0,1,0,25,25,25,25,2"),
        )
        .unwrap_err();
        assert_eq!(
            e.to_string(),
            "run.csv:3: column 13 `gear_odd`: 2 is not in the DBC value table of \
             DCT_Actuators.GearOddAct (0 N, 1 G1, 3 G3, 5 G5)"
        );
        for bad in ["1.5", "8", "-1"] {
            let e = Dataset::from_csv(
                "run.csv",
                &with(
                    ",gear_even",
                    &format!("0.01,4,0,100,0,0,1,0,25,25,25,25,{bad}"),
                ),
            )
            .unwrap_err();
            assert!(
                matches!(&e, DatasetError::NotInTable { column, index: 13, .. } if column == "gear_even"),
                "{e}"
            );
        }
        // Every gear of the table passes; so do the limits of the ranges.
        let ok = format!(
            "{HEADER},gear_odd,gear_even,pedal_pct\n0,4,0,100,0,0,1,0,-60,600,25,25,5,7,0\n0.01,4,0,100,0,0,1,0,25,25,25,25,3,6,100\n"
        );
        Dataset::from_csv("ok.csv", &ok).unwrap();
        // Non-finite values stay refused.
        let e = Dataset::from_csv("run.csv", &with("", "0.01,4,0,100,0,0,1,0,inf,25,25,25"))
            .unwrap_err();
        assert!(matches!(e, DatasetError::BadNumber { index: 9, .. }), "{e}");
    }

    #[test]
    fn gear_tables_come_from_the_dbc() {
        use crate::can::messages::{GearEvenAct, GearOddAct};
        let raws = |c: Col| -> Vec<u64> {
            c.gear_signal()
                .unwrap()
                .values
                .iter()
                .map(|v| v.0)
                .collect()
        };
        let odd: Vec<u64> = GearOddAct::ALL.iter().map(|g| *g as u64).collect();
        let even: Vec<u64> = GearEvenAct::ALL.iter().map(|g| *g as u64).collect();
        assert_eq!(raws(Col::GearOdd), odd);
        assert_eq!(raws(Col::GearEven), even);
        assert_eq!(Col::GearOdd.gear_signal().unwrap().name, "GearOddAct");
        assert_eq!(Col::GearEven.gear_signal().unwrap().name, "GearEvenAct");
        // The DBC ranges of the logged temperatures and the pedal lie inside the physical ranges
        // (a decoded frame cannot hold an impossible value the CSV check would refuse).
        use crate::can::messages::{BenchTemps, DctSensors, DrvPedal};
        for s in BenchTemps::def().signals.iter().chain(
            DctSensors::def()
                .signals
                .iter()
                .filter(|s| s.unit == "degC"),
        ) {
            assert!(
                s.min >= TEMP_RANGE_C.0 && s.max <= TEMP_RANGE_C.1,
                "{}",
                s.name
            );
        }
        let p = DrvPedal::accel_pedal_def();
        assert_eq!((p.min, p.max), (0.0, 100.0));
    }

    #[test]
    fn time_going_backwards_or_too_fine_is_refused() {
        let e = Dataset::from_csv("t.csv", &csv([0.0, 0.01, 0.005])).unwrap_err();
        assert!(
            matches!(
                e,
                DatasetError::TimeOrder {
                    line: 4,
                    index: 1,
                    ..
                }
            ),
            "{e}"
        );
        assert!(e
            .to_string()
            .starts_with("t.csv:4: column 1 `time_s`: 0.005 s goes backwards"));
        let e = Dataset::from_csv("t.csv", &csv([0.0, 0.01, 0.01005])).unwrap_err();
        assert!(matches!(e, DatasetError::TimeStep { line: 4, .. }), "{e}");
        assert!(
            e.to_string().contains("0.05 ms after the previous row"),
            "{e}"
        );
        // A 0.1 ms step is allowed (written with 4 decimals).
        let d = Dataset::from_csv("t.csv", &csv((0..50).map(|k| k as f64 * 1e-4))).unwrap();
        assert!((d.dt - 1e-4).abs() < 1e-9);
    }

    #[test]
    fn a_gap_cuts_the_record_into_segments_without_filling() {
        // 0–10 s at 10 ms, a 30 s hole, 40–50 s.
        let times: Vec<f64> = (0..=1000)
            .map(|k| k as f64 * 0.01)
            .chain((0..=1000).map(|k| 40.0 + k as f64 * 0.01))
            .collect();
        let text = csv(times.iter().copied());
        let s = Segments::from_csv("hole.csv", &text).unwrap();
        assert_eq!(s.datasets.len(), 2);
        assert_eq!(s.samples(), times.len());
        assert_eq!(s.datasets[0].source, "hole.csv[segment 1]");
        assert_eq!(s.datasets[1].source, "hole.csv[segment 2]");
        assert!((s.datasets[1].start_s - 40.0).abs() < 1e-9);
        assert!(s.datasets.iter().all(|d| d.stats.invalid_points == 0));
        assert_eq!(s.gaps.len(), 1);
        assert_eq!(s.gaps[0].line, 1003);
        assert!(s.dropped.is_empty());
        assert!(
            s.notes()[0].starts_with("hole.csv:1003: a gap in time of 30 s"),
            "{:?}",
            s.notes()
        );
        // The single-record loader refuses it rather than filling 30 s.
        let e = Dataset::from_csv("hole.csv", &text).unwrap_err();
        assert!(
            matches!(
                e,
                DatasetError::Gaps {
                    line: 1003,
                    segments: 2,
                    ..
                }
            ),
            "{e}"
        );
        // Short interpolation holes (below 5.5 steps) stay one record.
        let times: Vec<f64> = (0..=300)
            .filter(|k| !(100..104).contains(k))
            .map(|k| k as f64 * 0.01)
            .collect();
        let s = Segments::from_csv("small.csv", &csv(times)).unwrap();
        assert_eq!(s.datasets.len(), 1);
        assert_eq!(s.datasets[0].source, "small.csv");
        assert_eq!(s.datasets[0].len(), 301);
    }

    #[test]
    fn short_segments_are_left_out_short_records_refused() {
        // 0–10 s, a 20 s hole, 0.5 s, a hole, 40–45 s: the middle segment is left out.
        let times: Vec<f64> = (0..=1000)
            .map(|k| k as f64 * 0.01)
            .chain((0..=50).map(|k| 30.0 + k as f64 * 0.01))
            .chain((0..=500).map(|k| 40.0 + k as f64 * 0.01))
            .collect();
        let s = Segments::from_csv("mid.csv", &csv(times)).unwrap();
        assert_eq!(s.datasets.len(), 2);
        assert_eq!(s.datasets[1].source, "mid.csv[segment 3]");
        assert_eq!(s.dropped.len(), 1);
        assert_eq!(s.dropped[0].source, "mid.csv[segment 2]");
        assert_eq!(s.dropped[0].samples, 51);
        assert!(s
            .notes()
            .iter()
            .any(|n| n.contains("mid.csv[segment 2]") && n.contains("left out")));
        // A 1 s record.
        let e =
            Segments::from_csv("one.csv", &csv((0..=100).map(|k| k as f64 * 0.01))).unwrap_err();
        assert!(matches!(e, DatasetError::RecordTooShort { .. }), "{e}");
        assert!(
            e.to_string().starts_with("one.csv: the record lasts 1 s"),
            "{e}"
        );
        // Only short segments.
        let times: Vec<f64> = (0..=100)
            .map(|k| k as f64 * 0.01)
            .chain((0..=100).map(|k| 10.0 + k as f64 * 0.01))
            .collect();
        let e = Segments::from_csv("bits.csv", &csv(times)).unwrap_err();
        assert!(
            matches!(e, DatasetError::NoUsableSegment { segments: 2, .. }),
            "{e}"
        );
        // Long enough but no clutch ever closes.
        let text = csv((0..=300).map(|k| k as f64 * 0.01)).replace(",20,0,25", ",0,0,25");
        let e = Segments::from_csv("open.csv", &text).unwrap_err();
        assert!(matches!(e, DatasetError::NoEngagement { .. }), "{e}");
        assert!(e.to_string().starts_with("open.csv: no engagement"), "{e}");
    }
}
