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
//! hold); a grid point where a required signal has no sample within [`MAX_HOLD_S`] is marked
//! invalid in [`Dataset::valid`]. Errors name the file, line and column.

use crate::can::candump::{LogError, LogReader, LogRecord};
use crate::can::e2e::{is_protected, E2eChecker, E2eConfig, E2eError};
use crate::can::messages::{ids, Message};
use embedded_can::Frame as _;
use std::io::BufRead;
use std::path::Path;

/// rpm → rad/s.
pub const RPM_TO_RADPS: f64 = std::f64::consts::PI / 30.0;
/// Longest interval (s) over which a signal is interpolated before grid points are invalid.
pub const MAX_HOLD_S: f64 = 0.055;
/// Default resampling step (s): the contract's 10 ms cycle.
pub const DEFAULT_DT_S: f64 = 0.01;

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
    #[error("{file}: cannot read: {message}")]
    Io { file: String, message: String },
    #[error("{file}: empty file (expected a header line)")]
    Empty { file: String },
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
        "{file}:{line}: column {index} `time_s`: {value} does not increase (previous {previous})"
    )]
    TimeOrder {
        file: String,
        line: usize,
        index: usize,
        value: f64,
        previous: f64,
    },
    #[error("{file}: {rows} sample(s) — at least {min} are needed")]
    TooShort {
        file: String,
        rows: usize,
        min: usize,
    },
    #[error("{file}:{line}: malformed candump line: {message}")]
    LogLine {
        file: String,
        line: usize,
        message: String,
    },
    #[error("{file}: no valid {message} frame in the log: column(s) {columns} unavailable")]
    MissingMessage {
        file: String,
        message: &'static str,
        columns: String,
    },
    #[error("{file}: the required signals never overlap in time")]
    NoOverlap { file: String },
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

    /// Loads a CSV or candump file, chosen by content: a candump log starts with `(`.
    pub fn load(path: impl AsRef<Path>) -> Result<Dataset, DatasetError> {
        let path = path.as_ref();
        let file = path.display().to_string();
        let text = std::fs::read_to_string(path).map_err(|e| DatasetError::Io {
            file: file.clone(),
            message: e.to_string(),
        })?;
        if text.trim_start().starts_with('(') {
            Dataset::from_candump(&file, text.as_bytes(), DEFAULT_DT_S)
        } else {
            Dataset::from_csv(&file, &text)
        }
    }

    /// Parses CSV text (comma separated, one header line, `#` comment lines allowed).
    pub fn from_csv(file: &str, text: &str) -> Result<Dataset, DatasetError> {
        let mut lines = text
            .lines()
            .enumerate()
            .map(|(i, l)| (i + 1, l.trim_end_matches('\r')))
            .filter(|(_, l)| !l.trim().is_empty() && !l.trim_start().starts_with('#'));
        let Some((hline, header)) = lines.next() else {
            return Err(DatasetError::Empty { file: file.into() });
        };
        let names: Vec<&str> = header.split(',').map(str::trim).collect();
        let mut map: Vec<Option<Col>> = Vec::with_capacity(names.len());
        let mut time_idx = None;
        let mut seen = [false; NCOL];
        let mut stats = LoadStats::default();
        for (j, name) in names.iter().enumerate() {
            if *name == "time_s" {
                if time_idx.is_some() {
                    return Err(DatasetError::DuplicateColumn {
                        file: file.into(),
                        line: hline,
                        index: j + 1,
                        column: name.to_string(),
                    });
                }
                time_idx = Some(j);
                map.push(None);
                continue;
            }
            match Col::from_name(name) {
                Some(c) => {
                    if seen[c.idx()] {
                        return Err(DatasetError::DuplicateColumn {
                            file: file.into(),
                            line: hline,
                            index: j + 1,
                            column: name.to_string(),
                        });
                    }
                    seen[c.idx()] = true;
                    map.push(Some(c));
                }
                None => {
                    stats.ignored_columns.push(name.to_string());
                    map.push(None);
                }
            }
        }
        let Some(time_idx) = time_idx else {
            return Err(DatasetError::MissingColumn {
                file: file.into(),
                line: hline,
                column: "time_s".into(),
            });
        };
        for c in Col::ALL.iter().filter(|c| c.required()) {
            if !seen[c.idx()] {
                return Err(DatasetError::MissingColumn {
                    file: file.into(),
                    line: hline,
                    column: c.name().into(),
                });
            }
        }
        let mut t = Vec::new();
        let mut cols: Vec<Vec<f64>> = vec![Vec::new(); NCOL];
        for (line, l) in lines {
            let fields: Vec<&str> = l.split(',').map(str::trim).collect();
            if fields.len() != names.len() {
                return Err(DatasetError::FieldCount {
                    file: file.into(),
                    line,
                    expected: names.len(),
                    found: fields.len(),
                });
            }
            for (j, f) in fields.iter().enumerate() {
                let is_time = j == time_idx;
                let Some(c) = map[j] else {
                    if !is_time {
                        continue;
                    }
                    let v = parse_num(f).ok_or_else(|| DatasetError::BadNumber {
                        file: file.into(),
                        line,
                        index: j + 1,
                        column: "time_s".into(),
                        text: f.to_string(),
                    })?;
                    if let Some(&prev) = t.last() {
                        if v <= prev {
                            return Err(DatasetError::TimeOrder {
                                file: file.into(),
                                line,
                                index: j + 1,
                                value: v,
                                previous: prev,
                            });
                        }
                    }
                    t.push(v);
                    continue;
                };
                let v = parse_num(f).ok_or_else(|| DatasetError::BadNumber {
                    file: file.into(),
                    line,
                    index: j + 1,
                    column: c.name().into(),
                    text: f.to_string(),
                })?;
                cols[c.idx()].push(v);
            }
            stats.records += 1;
        }
        if t.len() < 2 {
            return Err(DatasetError::TooShort {
                file: file.into(),
                rows: t.len(),
                min: 2,
            });
        }
        let series: Vec<Option<Series>> = Col::ALL
            .iter()
            .map(|c| {
                seen[c.idx()].then(|| Series {
                    t: t.clone(),
                    v: std::mem::take(&mut cols[c.idx()]),
                })
            })
            .collect();
        // Keep the file's own step when it is uniform, else resample at its median step.
        let mut steps: Vec<f64> = t.windows(2).map(|w| w[1] - w[0]).collect();
        steps.sort_by(f64::total_cmp);
        let dt = steps[steps.len() / 2];
        let hold = (dt * 5.5).max(MAX_HOLD_S);
        resample(file, series, dt, hold, stats, false)
    }

    /// Decodes a candump log with the contract and resamples it at `dt` seconds.
    pub fn from_candump(file: &str, input: impl BufRead, dt: f64) -> Result<Dataset, DatasetError> {
        let records = LogReader::new(input).map(|r| {
            r.map_err(|e| match e {
                LogError::Line { line, kind } => DatasetError::LogLine {
                    file: file.into(),
                    line,
                    message: kind.to_string(),
                },
                LogError::Io(e) => DatasetError::Io {
                    file: file.into(),
                    message: e.to_string(),
                },
            })
        });
        Dataset::from_records(file, records, dt)
    }

    /// Decodes logged frames (e.g. straight from an in-process bus) and resamples them.
    pub fn from_records(
        file: &str,
        records: impl IntoIterator<Item = Result<LogRecord, DatasetError>>,
        dt: f64,
    ) -> Result<Dataset, DatasetError> {
        let mut raw = CandumpColumns::default();
        let mut stats = LoadStats::default();
        let mut checker: Option<E2eChecker> = None;
        let mut t0: Option<std::time::Duration> = None;
        for rec in records {
            let rec = rec?;
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
            let t = rec.timestamp.saturating_sub(start).as_secs_f64();
            if is_protected(id) {
                let ch =
                    checker.get_or_insert_with(|| E2eChecker::all(E2eConfig::default(), start));
                match ch.check(rec.timestamp, id, frame.bytes()) {
                    Ok(()) | Err(E2eError::CounterSkipped { .. }) => {}
                    Err(_) => {
                        stats.dropped_e2e += 1;
                        continue;
                    }
                }
            }
            let Ok(msg) = Message::decode(id, frame.bytes()) else {
                stats.undecodable += 1;
                continue;
            };
            raw.push(t, &msg);
        }
        raw.into_dataset(file, dt, stats)
    }
}

fn parse_num(s: &str) -> Option<f64> {
    s.parse::<f64>().ok().filter(|v| v.is_finite())
}

/// One signal's samples at its own times.
#[derive(Debug, Clone, Default)]
struct Series {
    t: Vec<f64>,
    v: Vec<f64>,
}

impl Series {
    fn push(&mut self, t: f64, v: f64) {
        // Logs are in time order; a frame with an older timestamp (reordering) is ignored.
        if self.t.last().is_none_or(|&last| t > last) {
            self.t.push(t);
            self.v.push(v);
        }
    }
}

/// A bench measurement sitting at its DBC range limit is clipped, not measured: NaN (the grid
/// points around it become invalid).
fn unsaturated(def: &crate::can::codec::MessageDef, si: usize, v: f64) -> f64 {
    let s = &def.signals[si];
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
}

impl CandumpColumns {
    fn col(&mut self, c: Col) -> &mut Series {
        if self.s.is_empty() {
            self.s = vec![Series::default(); NCOL];
        }
        &mut self.s[c.idx()]
    }

    fn push(&mut self, t: f64, m: &Message) {
        match m {
            Message::EngStatus(e) => {
                self.col(Col::Wf).push(t, e.eng_speed * RPM_TO_RADPS);
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
                    .push(t, f64::from(a.gear_odd_act as u8));
                self.col(Col::GearEven)
                    .push(t, f64::from(a.gear_even_act as u8));
            }
            Message::BenchTorque(b) => {
                let d = crate::can::messages::BenchTorque::def();
                self.col(Col::T1)
                    .push(t, unsaturated(d, 0, b.clutch1_torque));
                self.col(Col::T2)
                    .push(t, unsaturated(d, 1, b.clutch2_torque));
            }
            Message::BenchTemps(b) => {
                let d = crate::can::messages::BenchTemps::def();
                self.col(Col::Pp1)
                    .push(t, unsaturated(d, 0, b.pressure_plate1_temp));
                self.col(Col::Pp2)
                    .push(t, unsaturated(d, 1, b.pressure_plate2_temp));
                self.col(Col::Cd)
                    .push(t, unsaturated(d, 2, b.central_disk_temp));
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

    fn into_dataset(
        mut self,
        file: &str,
        dt: f64,
        stats: LoadStats,
    ) -> Result<Dataset, DatasetError> {
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
        let series: Vec<Option<Series>> = self
            .s
            .into_iter()
            .map(|s| (s.t.len() >= 2).then_some(s))
            .collect();
        resample(file, series, dt, MAX_HOLD_S, stats, true)
    }
}

/// Resamples every present series onto a uniform grid over the common span of the required ones.
///
/// `cycles` (bus logs): the grid is anchored at the plant's cycle clock (ENG_Status times) and a
/// sensor value at a grid point is the sample of the same cycle (the nearest within half a step;
/// linear interpolation only across a missing cycle), so frames sent a few microseconds apart
/// within one cycle are one sample; commands use zero-order hold. Otherwise (CSV rows) values
/// are interpolated linearly.
fn resample(
    file: &str,
    series: Vec<Option<Series>>,
    dt: f64,
    hold: f64,
    mut stats: LoadStats,
    cycles: bool,
) -> Result<Dataset, DatasetError> {
    let mut t_start = f64::NEG_INFINITY;
    let mut t_end = f64::INFINITY;
    for c in Col::ALL.iter().filter(|c| c.required()) {
        let s = series[c.idx()].as_ref().expect("required series present");
        t_start = t_start.max(s.t[0]);
        t_end = t_end.min(*s.t.last().expect("non-empty"));
    }
    if cycles {
        let clock = &series[Col::Wf.idx()]
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
        let mut out = Vec::with_capacity(n);
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
                let v = s.v[j] + (s.v[j + 1] - s.v[j]) * (t - ta) / (tb - ta);
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
        cols[c.idx()] = Some(out);
    }
    stats.invalid_points = valid.iter().filter(|v| !**v).count();
    Ok(Dataset {
        source: file.into(),
        time: grid.iter().map(|t| t - t_start).collect(),
        dt,
        cols,
        valid,
        stats,
    })
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
            DatasetError::TimeOrder {
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
}
