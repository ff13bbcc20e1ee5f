//! A DBC file given at run time (`ddct log decode --dbc FILE`), parsed with the `can-dbc` crate
//! (the DBC grammar cantools reads), and a decoder of logged frames with it.
//!
//! The built-in contract stays generated at build time from `dbc/ddct.dbc` by `build.rs` (the same
//! `can-dbc` parser, through the contract subset of [`super::dbc`]); this module is only for a
//! foreign or edited DBC.
//!
//! Decoding follows cantools:
//! - Intel (`@1`) signals count their start bit from the least significant bit of byte 0 upwards;
//!   Motorola (`@0`) signals name their most significant bit in the DBC's sawtooth numbering
//!   (bit 7 of byte 0 is 7, bit 0 of byte 1 is 8) and run towards less significant bits, across
//!   bytes in network order.
//! - physical = raw · factor + offset; `-` signals are two's complement; `SIG_VALTYPE_` 1 and 2
//!   signals are IEEE single and double floats.
//! - Value tables (`VAL_`) name raw values; the name is shown where the built-in decoder shows one.
//! - Multiplexing: the multiplexor (`M`) is always decoded, a multiplexed signal (`m3`) only when
//!   its multiplexor is active and holds its value; extended multiplexing (`SG_MUL_VAL_`, `m3M`)
//!   with value ranges is followed the same way. A multiplexor value that selects no signal is
//!   reported on the frame, as cantools does.
//! - A frame shorter than the message is reported (the signals inside the received bytes are
//!   still shown); a longer one is decoded from its first bytes (cantools' default).
//!
//! The E2E verdict (alive counter, CRC, sequence) is computed only for a message that is an
//! E2E-protected message of the built-in contract with the same standard id, the same length and
//! the same signals at the same bits (names, start bits, lengths, Intel order, signedness); for
//! every other frame it is "not computed" (`None`).

use super::candump::LogRecord;
use super::codec::{decimals_of, MessageDef};
use super::decode::{E2eVerdict, Gap, InputLoss, Silences};
use super::e2e::{E2eChecker, E2eConfig};
use super::messages::message_def;
use embedded_can::Frame as _;
use std::collections::HashMap;
use std::fmt;
use std::path::{Path, PathBuf};
use thiserror::Error;

/// Why a DBC file could not be used.
#[derive(Debug, Error)]
pub enum RuntimeDbcError {
    #[error("reading the DBC file {}", path.display())]
    Read {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error("{}: neither UTF-8 nor Windows-1252 text", path.display())]
    Encoding { path: PathBuf },
    #[error("{}{}: not a DBC file the parser (can-dbc) reads", path.display(), position(*line, *column))]
    Parse {
        path: PathBuf,
        /// 1-based line and column of a syntax error, when the parser reports them.
        line: Option<usize>,
        column: Option<usize>,
        #[source]
        source: can_dbc::DbcError,
    },
    #[error("{}: the DBC parser (can-dbc) failed on this file", path.display())]
    ParserPanicked { path: PathBuf },
    #[error("{}: {message}.{signal}: {problem}", path.display())]
    Signal {
        path: PathBuf,
        message: String,
        signal: String,
        problem: String,
    },
}

fn position(line: Option<usize>, column: Option<usize>) -> String {
    match (line, column) {
        (Some(l), Some(c)) => format!(":{l}:{c}"),
        (Some(l), None) => format!(":{l}"),
        _ => String::new(),
    }
}

/// Bit numbering of a signal.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ByteOrder {
    /// `@1`: start bit is the least significant bit, counted upwards from bit 0 of byte 0.
    Intel,
    /// `@0`: start bit is the most significant bit in the sawtooth numbering.
    Motorola,
}

/// How the raw bits become a number.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Kind {
    Integer,
    /// `SIG_VALTYPE_ ... : 1;` (32 bits).
    Float32,
    /// `SIG_VALTYPE_ ... : 2;` (64 bits).
    Float64,
}

/// When a signal is present in a frame.
#[derive(Debug, Clone, PartialEq)]
pub enum Mux {
    /// Always (plain signals and multiplexors that are not multiplexed themselves).
    Always,
    /// When signal `switch` (an index into the message's signals) is present and its raw value
    /// lies in one of the inclusive ranges.
    When {
        switch: usize,
        ranges: Vec<(u64, u64)>,
    },
}

/// One signal of a runtime DBC.
#[derive(Debug, Clone, PartialEq)]
pub struct Signal {
    pub name: String,
    pub start_bit: u32,
    pub length: u32,
    pub order: ByteOrder,
    pub signed: bool,
    pub kind: Kind,
    pub factor: f64,
    pub offset: f64,
    pub min: f64,
    pub max: f64,
    pub unit: String,
    /// Value table: raw value → name.
    pub values: Vec<(i64, String)>,
    pub mux: Mux,
    /// Other signals of the message are multiplexed by this one.
    pub is_multiplexor: bool,
}

/// One message of a runtime DBC.
#[derive(Debug, Clone, PartialEq)]
pub struct Message {
    pub id: u32,
    pub extended: bool,
    pub name: String,
    pub size: usize,
    /// `GenMsgCycleTime` (ms), 0 when absent: the basis of the `gap:` notices.
    pub cycle_ms: u32,
    pub signals: Vec<Signal>,
    /// The contract's message when this one is it (same id, length and signal bits) and is
    /// E2E protected: only then is the E2E verdict computed.
    pub e2e_twin: Option<&'static MessageDef>,
}

/// A DBC file loaded at run time.
#[derive(Debug, Clone, PartialEq)]
pub struct RuntimeDbc {
    pub path: PathBuf,
    pub messages: Vec<Message>,
    by_id: HashMap<(u32, bool), usize>,
}

impl RuntimeDbc {
    /// Reads and parses a DBC file (UTF-8, or Windows-1252 as cantools reads by default).
    pub fn load(path: &Path) -> Result<Self, RuntimeDbcError> {
        let bytes = std::fs::read(path).map_err(|source| RuntimeDbcError::Read {
            path: path.to_path_buf(),
            source,
        })?;
        let text = match std::str::from_utf8(&bytes) {
            Ok(t) => std::borrow::Cow::Borrowed(t),
            Err(_) => can_dbc::decode_cp1252(&bytes).ok_or_else(|| RuntimeDbcError::Encoding {
                path: path.to_path_buf(),
            })?,
        };
        Self::parse(path, &text)
    }

    /// Parses DBC text; `path` names it in errors.
    pub fn parse(path: &Path, text: &str) -> Result<Self, RuntimeDbcError> {
        let text = text.strip_prefix('\u{feff}').unwrap_or(text);
        // A fault inside the parser must not take the command down with a panic.
        let parsed = std::panic::catch_unwind(|| can_dbc::Dbc::try_from(text)).map_err(|_| {
            RuntimeDbcError::ParserPanicked {
                path: path.to_path_buf(),
            }
        })?;
        let dbc = parsed.map_err(|source| {
            let (line, column) = match &source {
                can_dbc::DbcError::Pest(e) => match e.line_col {
                    pest::error::LineColLocation::Pos((l, c))
                    | pest::error::LineColLocation::Span((l, c), _) => (Some(l), Some(c)),
                },
                _ => (None, None),
            };
            RuntimeDbcError::Parse {
                path: path.to_path_buf(),
                line,
                column,
                source,
            }
        })?;
        Self::from_dbc(path, &dbc)
    }

    fn from_dbc(path: &Path, dbc: &can_dbc::Dbc) -> Result<Self, RuntimeDbcError> {
        let mut messages: Vec<Message> = Vec::new();
        let mut by_id = HashMap::new();
        for m in &dbc.messages {
            // The pseudo message of signals without a message (Vector tools) carries no frames.
            if m.name == "VECTOR__INDEPENDENT_SIG_MSG" {
                continue;
            }
            let msg = convert_message(path, dbc, m)?;
            // A later message with the same id replaces the earlier one, as in cantools.
            match by_id.get(&(msg.id, msg.extended)) {
                Some(&i) => messages[i] = msg,
                None => {
                    by_id.insert((msg.id, msg.extended), messages.len());
                    messages.push(msg);
                }
            }
        }
        Ok(Self {
            path: path.to_path_buf(),
            messages,
            by_id,
        })
    }

    /// The message of a frame id.
    pub fn message(&self, id: u32, extended: bool) -> Option<&Message> {
        self.by_id.get(&(id, extended)).map(|&i| &self.messages[i])
    }

    /// A message by name.
    pub fn message_by_name(&self, name: &str) -> Option<&Message> {
        self.messages.iter().find(|m| m.name == name)
    }
}

fn numeric(v: &can_dbc::NumericValue) -> f64 {
    match *v {
        can_dbc::NumericValue::Uint(u) => u as f64,
        can_dbc::NumericValue::Int(i) => i as f64,
        can_dbc::NumericValue::Double(d) => d,
    }
}

fn attribute_ms(v: Option<&can_dbc::AttributeValue>) -> u32 {
    match v {
        Some(can_dbc::AttributeValue::Uint(u)) => u32::try_from(*u).unwrap_or(0),
        Some(can_dbc::AttributeValue::Int(i)) => u32::try_from(*i).unwrap_or(0),
        Some(can_dbc::AttributeValue::Double(d)) if d.is_finite() && *d >= 0.0 => {
            d.round().min(f64::from(u32::MAX)) as u32
        }
        _ => 0,
    }
}

fn convert_message(
    path: &Path,
    dbc: &can_dbc::Dbc,
    m: &can_dbc::Message,
) -> Result<Message, RuntimeDbcError> {
    let bad = |signal: &str, problem: String| RuntimeDbcError::Signal {
        path: path.to_path_buf(),
        message: m.name.clone(),
        signal: signal.to_string(),
        problem,
    };
    let (id, extended) = match m.id {
        can_dbc::MessageId::Standard(id) => (u32::from(id), false),
        can_dbc::MessageId::Extended(id) => (id, true),
    };
    let index: HashMap<&str, usize> = m
        .signals
        .iter()
        .enumerate()
        .map(|(i, s)| (s.name.as_str(), i))
        .collect();
    // Plain multiplexors (`M`): the switch of `mN` signals without an SG_MUL_VAL_ line.
    let plain_switches: Vec<usize> = m
        .signals
        .iter()
        .enumerate()
        .filter(|(_, s)| s.multiplexer_indicator == can_dbc::MultiplexIndicator::Multiplexor)
        .map(|(i, _)| i)
        .collect();
    let within = InMessage {
        dbc,
        m,
        index: &index,
        plain_switches: &plain_switches,
    };
    let signals = m
        .signals
        .iter()
        .map(|s| within.signal(s).map_err(|p| bad(&s.name, p)));
    let mut signals = signals.collect::<Result<Vec<_>, _>>()?;
    for i in 0..signals.len() {
        if let Mux::When { switch, .. } = signals[i].mux {
            signals[switch].is_multiplexor = true;
        }
    }
    let mut msg = Message {
        id,
        extended,
        name: m.name.clone(),
        size: usize::try_from(m.size).unwrap_or(usize::MAX),
        cycle_ms: attribute_ms(dbc.resolved_message_attribute(m.id, "GenMsgCycleTime")),
        signals,
        e2e_twin: None,
    };
    msg.e2e_twin = e2e_twin(&msg);
    Ok(msg)
}

/// A message of the DBC as its signals' conversion reads it: the DBC, the message, its signals'
/// indices by name and its plain multiplexors (`M`).
struct InMessage<'a> {
    dbc: &'a can_dbc::Dbc,
    m: &'a can_dbc::Message,
    index: &'a HashMap<&'a str, usize>,
    plain_switches: &'a [usize],
}

impl InMessage<'_> {
    /// One signal of the message in the decoder's terms; an error is the problem with it, in words.
    fn signal(&self, s: &can_dbc::Signal) -> Result<Signal, String> {
        let (dbc, m) = (self.dbc, self.m);
        let length = u32::try_from(s.size).unwrap_or(u32::MAX);
        if !(1..=64).contains(&length) {
            return Err(format!("length {} bits (1 to 64 are decoded)", s.size));
        }
        let start_bit = u32::try_from(s.start_bit)
            .ok()
            .filter(|b| *b < 512)
            .ok_or_else(|| format!("start bit {} beyond 64 bytes", s.start_bit))?;
        let kind = match dbc.extended_value_type_for_signal(m.id, &s.name) {
            Some(can_dbc::SignalExtendedValueType::IEEEfloat32Bit) => Kind::Float32,
            Some(can_dbc::SignalExtendedValueType::IEEEdouble64bit) => Kind::Float64,
            _ => Kind::Integer,
        };
        match (kind, length) {
            (Kind::Float32, 32) | (Kind::Float64, 64) | (Kind::Integer, _) => {}
            _ => return Err(format!("a {kind:?} signal of {length} bits (SIG_VALTYPE_)")),
        }
        let values = dbc
            .value_descriptions_for_signal(m.id, &s.name)
            .map(|v| {
                v.iter()
                    .map(|d| (d.id, d.description.clone()))
                    .collect::<Vec<_>>()
            })
            .unwrap_or_default();
        Ok(Signal {
            name: s.name.clone(),
            start_bit,
            length,
            order: match s.byte_order {
                can_dbc::ByteOrder::LittleEndian => ByteOrder::Intel,
                can_dbc::ByteOrder::BigEndian => ByteOrder::Motorola,
            },
            signed: s.value_type == can_dbc::ValueType::Signed,
            kind,
            factor: s.factor,
            offset: s.offset,
            min: numeric(&s.min),
            max: numeric(&s.max),
            unit: s.unit.clone(),
            values,
            mux: self.mux(s)?,
            is_multiplexor: false,
        })
    }

    /// When signal `s` of the message is present: always, or for the values of its multiplexor
    /// that its `SG_MUL_VAL_` ranges (extended multiplexing) or its `mN` (the message's one plain
    /// multiplexor `M`) give.
    fn mux(&self, s: &can_dbc::Signal) -> Result<Mux, String> {
        let (dbc, m, index, plain_switches) = (self.dbc, self.m, self.index, self.plain_switches);
        let selector = match s.multiplexer_indicator {
            can_dbc::MultiplexIndicator::MultiplexedSignal(v)
            | can_dbc::MultiplexIndicator::MultiplexorAndMultiplexedSignal(v) => Some(v),
            _ => None,
        };
        let extended_mux = dbc
            .extended_multiplex
            .iter()
            .find(|e| e.message_id == m.id && e.signal_name == s.name);
        match (selector, extended_mux) {
            (Some(_), Some(e)) => {
                let switch = *index
                    .get(e.multiplexor_signal_name.as_str())
                    .ok_or_else(|| {
                        format!(
                            "SG_MUL_VAL_ names the multiplexor {}, not a signal of the message",
                            e.multiplexor_signal_name
                        )
                    })?;
                Ok(Mux::When {
                    switch,
                    ranges: e
                        .mappings
                        .iter()
                        .map(|r| (r.min_value, r.max_value))
                        .collect(),
                })
            }
            (Some(v), None) => match plain_switches {
                [switch] => Ok(Mux::When {
                    switch: *switch,
                    ranges: vec![(v, v)],
                }),
                [] => Err("multiplexed (m) but the message has no multiplexor (M)".into()),
                _ => Err(
                    "multiplexed (m) in a message of several multiplexors without SG_MUL_VAL_"
                        .into(),
                ),
            },
            (None, _) => Ok(Mux::Always),
        }
    }
}

/// The contract's E2E-protected message with this message's id, length and signal bits.
fn e2e_twin(m: &Message) -> Option<&'static MessageDef> {
    if m.extended {
        return None;
    }
    let def = message_def(m.id).filter(|d| d.e2e && d.dlc == m.size)?;
    let same = def.signals.len() == m.signals.len()
        && def.signals.iter().all(|c| {
            m.signals.iter().any(|s| {
                s.name == c.name
                    && s.start_bit == c.start_bit
                    && s.length == c.length
                    && s.order == ByteOrder::Intel
                    && s.signed == c.signed
                    && s.kind == Kind::Integer
                    && s.mux == Mux::Always
            })
        });
    same.then_some(def)
}

impl Signal {
    /// The signal's bits as an unsigned number, or `None` when they reach past `data`.
    pub fn bits(&self, data: &[u8]) -> Option<u64> {
        let mut v = 0u64;
        match self.order {
            ByteOrder::Intel => {
                for i in 0..self.length {
                    let p = (self.start_bit + i) as usize;
                    let byte = *data.get(p / 8)?;
                    v |= u64::from((byte >> (p % 8)) & 1) << i;
                }
            }
            ByteOrder::Motorola => {
                // The most significant bit in network (MSB-first) numbering, then onwards.
                let first = 8 * (self.start_bit / 8) + (7 - self.start_bit % 8);
                for i in 0..self.length {
                    let q = (first + i) as usize;
                    let byte = *data.get(q / 8)?;
                    v = (v << 1) | u64::from((byte >> (7 - q % 8)) & 1);
                }
            }
        }
        Some(v)
    }

    /// The raw value of the bits (two's complement for signed integers) as an integer.
    pub fn raw_integer(&self, bits: u64) -> i128 {
        if self.signed && self.length < 64 && (bits >> (self.length - 1)) & 1 == 1 {
            i128::from(bits) - (1i128 << self.length)
        } else if self.signed {
            i128::from(bits as i64)
        } else {
            i128::from(bits)
        }
    }

    /// Physical value of the bits.
    pub fn physical(&self, bits: u64) -> f64 {
        let raw = match self.kind {
            Kind::Integer => self.raw_integer(bits) as f64,
            Kind::Float32 => f64::from(f32::from_bits(bits as u32)),
            Kind::Float64 => f64::from_bits(bits),
        };
        raw * self.factor + self.offset
    }

    /// The value-table name of the bits, if any.
    pub fn label(&self, bits: u64) -> Option<&str> {
        if self.kind != Kind::Integer {
            return None;
        }
        let raw = self.raw_integer(bits);
        self.values
            .iter()
            .find(|(r, _)| i128::from(*r) == raw)
            .map(|(_, l)| l.as_str())
    }

    /// Inside `[min, max]` (half a step of tolerance); `[0|0]` means no range, as in DBC tools.
    pub fn in_range(&self, v: f64) -> bool {
        if self.min == 0.0 && self.max == 0.0 {
            return true;
        }
        let tol = self.factor.abs() * 0.5;
        v >= self.min - tol && v <= self.max + tol
    }
}

/// One decoded signal.
#[derive(Debug, Clone, PartialEq)]
pub struct Value<'a> {
    pub signal: &'a Signal,
    pub bits: u64,
    pub value: f64,
    pub label: Option<&'a str>,
    pub in_range: bool,
}

impl Value<'_> {
    /// The value-table name, else the number with the decimals of the signal's resolution
    /// (floats in full).
    pub fn display_value(&self) -> String {
        if let Some(l) = self.label {
            return l.to_string();
        }
        match self.signal.kind {
            Kind::Integer => format!("{:.*}", decimals_of(self.signal.factor), self.value),
            Kind::Float32 | Kind::Float64 => format!("{}", self.value),
        }
    }
}

/// What is wrong with one frame (the frame is still shown).
#[derive(Debug, Clone, PartialEq)]
pub enum FrameIssue {
    /// The id is not a message of the DBC.
    UnknownId { id: u32, extended: bool },
    /// Fewer data bytes than the message's length.
    Short {
        message: String,
        expected: usize,
        found: usize,
    },
    /// A multiplexor value for which the DBC has no multiplexed signal.
    MuxValue {
        message: String,
        multiplexor: String,
        value: u64,
    },
}

impl fmt::Display for FrameIssue {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            FrameIssue::UnknownId { id, extended } => {
                let kind = if *extended { "extended " } else { "" };
                write!(f, "{kind}id {id:#x} is not a message of the DBC")
            }
            FrameIssue::Short {
                message,
                expected,
                found,
            } => write!(f, "{message}: {found} data bytes, the DBC says {expected}"),
            FrameIssue::MuxValue {
                message,
                multiplexor,
                value,
            } => write!(
                f,
                "{message}: multiplexor {multiplexor} = {value} selects no signal of the DBC"
            ),
        }
    }
}

/// One decoded frame.
#[derive(Debug, Clone, PartialEq)]
pub struct Decoded<'a> {
    pub message: Option<&'a Message>,
    /// The signals present in the frame (the active multiplexed ones among them), in DBC order.
    pub signals: Vec<Value<'a>>,
    /// `None`: not computed (the message is not an E2E message of the contract, see the module
    /// doc).
    pub e2e: Option<E2eVerdict>,
    pub issue: Option<FrameIssue>,
}

/// Decodes a frame sequence with a runtime DBC (E2E and gap state carry over between frames).
pub struct Decoder<'a> {
    dbc: &'a RuntimeDbc,
    config: E2eConfig,
    checker: Option<E2eChecker>,
    silences: Silences<'a, usize>,
    loss: InputLoss,
}

impl<'a> Decoder<'a> {
    /// The logger before this decoder lost `frames` frames here (a `DROPCOUNT` line).
    pub fn input_lost(&mut self, frames: u64) {
        self.loss.lost(frames);
    }

    /// Frames the logger reported lost so far.
    pub fn frames_lost(&self) -> u64 {
        self.loss.total()
    }

    pub fn new(dbc: &'a RuntimeDbc, config: E2eConfig) -> Self {
        Self {
            dbc,
            config,
            checker: None,
            loss: InputLoss::default(),
            silences: Silences::default(),
        }
    }

    /// Decodes one record.
    pub fn decode(&mut self, r: &LogRecord) -> Decoded<'a> {
        let dbc = self.dbc;
        let id = r.frame.raw_id();
        let extended = r.frame.is_extended();
        if r.frame.is_remote_frame() {
            return Decoded {
                message: None,
                signals: Vec::new(),
                e2e: None,
                issue: None,
            };
        }
        let Some(&mi) = dbc.by_id.get(&(id, extended)) else {
            return Decoded {
                message: None,
                signals: Vec::new(),
                e2e: None,
                issue: Some(FrameIssue::UnknownId { id, extended }),
            };
        };
        let m = &dbc.messages[mi];
        let data = r.frame.bytes();
        self.silences.seen(
            mi,
            &m.name,
            u64::from(m.cycle_ms),
            u64::from(self.config.timeout_cycles),
            r.timestamp,
        );
        let e2e = m.e2e_twin.map(|def| {
            let twins = dbc.messages.iter().filter_map(|m| m.e2e_twin.map(|d| d.id));
            let checker = self
                .checker
                .get_or_insert_with(|| E2eChecker::for_ids(self.config, r.timestamp, twins));
            let v = match checker.check(r.timestamp, u32::from(def.id), data) {
                Ok(()) => E2eVerdict::Ok,
                Err(e) => E2eVerdict::Failed(e),
            };
            self.loss.explain(u32::from(def.id), v)
        });
        let (signals, mux_issue) = decode_signals(m, data);
        let issue = if data.len() < m.size {
            Some(FrameIssue::Short {
                message: m.name.clone(),
                expected: m.size,
                found: data.len(),
            })
        } else {
            mux_issue
        };
        Decoded {
            message: Some(m),
            signals,
            e2e,
            issue,
        }
    }

    /// Silences longer than the timeout seen so far.
    pub fn gaps(&self) -> &[Gap<'a>] {
        self.silences.gaps()
    }
}

/// Presence of each signal of `m` in `data`: `Some(bits)` when present.
fn present(m: &Message, data: &[u8]) -> Vec<Option<u64>> {
    #[derive(Clone, Copy, PartialEq)]
    enum State {
        Todo,
        Busy,
        Done(Option<u64>),
    }
    fn visit(m: &Message, data: &[u8], i: usize, st: &mut [State]) -> Option<u64> {
        match st[i] {
            State::Done(v) => return v,
            // A multiplexor cycle: nothing in it is present.
            State::Busy => return None,
            State::Todo => {}
        }
        st[i] = State::Busy;
        let s = &m.signals[i];
        let v = match &s.mux {
            Mux::Always => s.bits(data),
            Mux::When { switch, ranges } => visit(m, data, *switch, st)
                .filter(|sw| ranges.iter().any(|(lo, hi)| (lo..=hi).contains(&sw)))
                .and_then(|_| s.bits(data)),
        };
        st[i] = State::Done(v);
        v
    }
    let mut st = vec![State::Todo; m.signals.len()];
    (0..m.signals.len())
        .map(|i| visit(m, data, i, &mut st))
        .collect()
}

fn decode_signals<'a>(m: &'a Message, data: &[u8]) -> (Vec<Value<'a>>, Option<FrameIssue>) {
    let bits = present(m, data);
    let values = m
        .signals
        .iter()
        .zip(&bits)
        .filter_map(|(s, b)| {
            let b = (*b)?;
            let value = s.physical(b);
            Some(Value {
                signal: s,
                bits: b,
                value,
                label: s.label(b),
                in_range: s.in_range(value),
            })
        })
        .collect();
    // A present multiplexor whose value selects none of its multiplexed signals.
    let issue = m.signals.iter().enumerate().find_map(|(i, s)| {
        let value = bits[i].filter(|_| s.is_multiplexor)?;
        let selects = m.signals.iter().zip(&bits).any(|(t, b)| {
            b.is_some() && matches!(&t.mux, Mux::When { switch, .. } if *switch == i)
        });
        (!selects).then(|| FrameIssue::MuxValue {
            message: m.name.clone(),
            multiplexor: s.name.clone(),
            value,
        })
    });
    (values, issue)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::can::candump::parse_line;
    use crate::can::e2e::E2eSender;
    use crate::can::messages::{ids, EngStatus};
    use crate::can::CanFrame;
    use std::time::Duration;

    const FOREIGN: &str = r#"VERSION ""

NS_ :
	CM_
	VAL_

BS_:

BU_: ECU GW

BO_ 1280 Motion: 8 ECU
 SG_ Speed : 7|16@0- (0.01,0) [-327.68|327.67] "m/s" GW
 SG_ Temp : 16|12@1+ (0.1,-40) [-40|369.5] "degC" GW
 SG_ Mode : 28|3@1+ (1,0) [0|7] "" GW
 SG_ Odd : 37|11@0+ (1,0) [0|2047] "" GW

BO_ 2566848741 Ext: 4 ECU
 SG_ Ratio : 0|32@1+ (1,0) [0|0] "" GW

BO_ 1536 Muxed: 8 ECU
 SG_ Sel M : 0|8@1+ (1,0) [0|255] "" GW
 SG_ A m1 : 8|16@1+ (1,0) [0|0] "" GW
 SG_ B m2 : 8|16@1- (0.5,0) [0|0] "" GW

CM_ SG_ 1280 Speed "Signed big-endian";
VAL_ 1280 Mode 0 "Off" 1 "Eco" 2 "Sport" ;
SIG_VALTYPE_ 2566848741 Ratio : 1;
"#;

    fn dbc() -> RuntimeDbc {
        RuntimeDbc::parse(Path::new("foreign.dbc"), FOREIGN).unwrap()
    }

    fn rec(line: &str) -> LogRecord {
        parse_line(line).unwrap()
    }

    fn values(d: &Decoded<'_>) -> Vec<(String, f64)> {
        d.signals
            .iter()
            .map(|v| (v.signal.name.clone(), v.value))
            .collect()
    }

    #[test]
    fn intel_and_motorola_bits_as_cantools_numbers_them() {
        let db = dbc();
        let m = db.message(1280, false).unwrap();
        assert_eq!(m.name, "Motion");
        // Speed: MSB at bit 7 of byte 0, 16 bits big-endian: bytes 0..2 = 0xFF38 = -200.
        // Temp: Intel bits 16..28: 0x1F4 = 500 -> 500*0.1-40 = 10. Mode: bits 28..31 = 2.
        // Odd: MSB at bit 5 of byte 4 (sawtooth 37), 11 bits: bits 5..0 of byte 4 then 7..3 of
        // byte 5: byte 4 = 0b0010_1010 -> 101010, byte 5 = 0b1100_1000 -> 11001.
        let data = [0xFF, 0x38, 0xF4, 0x21, 0x2A, 0xC8, 0, 0];
        let f = CanFrame::standard(1280, &data).unwrap();
        let mut d = Decoder::new(&db, E2eConfig::default());
        let r = LogRecord {
            timestamp: Duration::ZERO,
            iface: "can0".into(),
            frame: f,
            direction: None,
        };
        let out = d.decode(&r);
        let v = values(&out);
        assert_eq!(v[0].0, "Speed");
        assert!((v[0].1 - -2.0).abs() < 1e-12, "{v:?}");
        assert!((v[1].1 - 10.0).abs() < 1e-9, "{v:?}");
        assert_eq!(v[2].1, 2.0);
        assert_eq!(out.signals[2].label, Some("Sport"));
        assert_eq!(out.signals[2].display_value(), "Sport");
        // 101010 then 11001.
        assert_eq!(v[3].1, f64::from(0b101_0101_1001_u32));
        assert_eq!(out.e2e, None);
        assert_eq!(out.issue, None);
        assert_eq!(out.signals[0].display_value(), "-2.00");
    }

    #[test]
    fn floats_extended_ids_and_unknown_ids() {
        let db = dbc();
        let m = db.message(0x18FF_00E5, true).unwrap();
        assert_eq!(m.signals[0].kind, Kind::Float32);
        let bytes = 1.5f32.to_le_bytes();
        let line = format!(
            "(1.000000) can0 18FF00E5#{}",
            bytes.iter().map(|b| format!("{b:02X}")).collect::<String>()
        );
        let mut d = Decoder::new(&db, E2eConfig::default());
        assert_eq!(values(&d.decode(&rec(&line))), [("Ratio".into(), 1.5)]);
        // The same number as a standard id is not that message.
        let out = d.decode(&rec("(1.000000) can0 0E5#00"));
        assert_eq!(out.message, None);
        assert_eq!(
            out.issue.unwrap().to_string(),
            "id 0xe5 is not a message of the DBC"
        );
    }

    #[test]
    fn multiplexed_signals_follow_their_multiplexor() {
        let db = dbc();
        let mut d = Decoder::new(&db, E2eConfig::default());
        let out = d.decode(&rec("(1.000000) can0 600#01FEFF0000000000"));
        assert_eq!(values(&out), [("Sel".into(), 1.0), ("A".into(), 65534.0)]);
        let out = d.decode(&rec("(1.000000) can0 600#02FEFF0000000000"));
        assert_eq!(values(&out), [("Sel".into(), 2.0), ("B".into(), -1.0)]);
        let out = d.decode(&rec("(1.000000) can0 600#03FEFF0000000000"));
        assert_eq!(values(&out), [("Sel".into(), 3.0)]);
        assert!(matches!(
            out.issue,
            Some(FrameIssue::MuxValue { value: 3, .. })
        ));
    }

    #[test]
    fn extended_multiplexing_with_ranges() {
        let text = r#"VERSION ""
NS_ :
BS_:
BU_: A
BO_ 100 M: 8 A
 SG_ S0 M : 0|4@1+ (1,0) [0|0] "" A
 SG_ S1 m1M : 4|4@1+ (1,0) [0|0] "" A
 SG_ X m2 : 8|8@1+ (1,0) [0|0] "" A
SG_MUL_VAL_ 100 S1 S0 1-1;
SG_MUL_VAL_ 100 X S1 2-5;
"#;
        let db = RuntimeDbc::parse(Path::new("x.dbc"), text).unwrap();
        let mut d = Decoder::new(&db, E2eConfig::default());
        let names = |d: &Decoded<'_>| -> Vec<String> {
            d.signals.iter().map(|v| v.signal.name.clone()).collect()
        };
        assert_eq!(
            names(&d.decode(&rec("(1.000000) c 064#3107"))),
            ["S0", "S1", "X"]
        );
        assert_eq!(
            names(&d.decode(&rec("(1.000000) c 064#6107"))),
            ["S0", "S1"]
        );
        assert_eq!(names(&d.decode(&rec("(1.000000) c 064#3207"))), ["S0"]);
    }

    #[test]
    fn short_frames_are_reported_and_decode_what_fits() {
        let db = dbc();
        let mut d = Decoder::new(&db, E2eConfig::default());
        let out = d.decode(&rec("(1.000000) can0 500#FF38"));
        assert_eq!(values(&out).len(), 1);
        assert_eq!(
            out.issue.unwrap().to_string(),
            "Motion: 2 data bytes, the DBC says 8"
        );
    }

    #[test]
    fn the_contract_as_a_runtime_dbc_decodes_like_the_builtin_decoder_with_e2e() {
        let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("dbc/ddct.dbc");
        let db = RuntimeDbc::load(&path).unwrap();
        let m = db.message(u32::from(ids::ENG_STATUS), false).unwrap();
        assert_eq!(m.cycle_ms, 10);
        assert!(m.e2e_twin.is_some());
        assert!(db
            .message_by_name("BENCH_Torque")
            .unwrap()
            .e2e_twin
            .is_none());
        let mut tx = E2eSender::new();
        let mut data = EngStatus {
            eng_speed: 812.5,
            eng_torque_act: -12.3,
            ..Default::default()
        }
        .encode()
        .unwrap();
        tx.protect(ids::ENG_STATUS, &mut data);
        let r = LogRecord {
            timestamp: Duration::from_millis(5),
            iface: "vcan0".into(),
            frame: CanFrame::standard(ids::ENG_STATUS, &data).unwrap(),
            direction: None,
        };
        let mut builtin = crate::can::decode::LogDecoder::default();
        let want = builtin.decode(&r);
        let mut d = Decoder::new(&db, E2eConfig::default());
        let got = d.decode(&r);
        assert_eq!(got.e2e, Some(E2eVerdict::Ok));
        assert_eq!(got.signals.len(), want.signals.len());
        for (g, w) in got.signals.iter().zip(&want.signals) {
            assert_eq!((g.signal.name.as_str(), g.value), (w.signal.name, w.value));
        }
        // The same frame again: the counter repeats, as the built-in decoder says too.
        assert_eq!(
            d.decode(&r).e2e.map(|v| v.as_str()),
            Some(builtin.decode(&r).e2e.as_str())
        );
    }

    #[test]
    fn a_changed_layout_loses_the_e2e_verdict() {
        let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("dbc/ddct.dbc");
        let text = std::fs::read_to_string(&path)
            .unwrap()
            .replace("SG_ EngSpeed : 0|16@1+", "SG_ EngSpeed : 0|15@1+");
        let db = RuntimeDbc::parse(&path, &text).unwrap();
        assert!(db.message_by_name("ENG_Status").unwrap().e2e_twin.is_none());
        assert!(db.message_by_name("DRV_Pedal").unwrap().e2e_twin.is_some());
    }

    #[test]
    fn syntax_errors_name_the_file_and_position() {
        let text =
            "VERSION \"\"\n\nBO_ 12 Broken: 8 ECU\n SG_ X : 0|8@1+ (1,0) [0|1] \"\" ECU oops (\n";
        let e = RuntimeDbc::parse(Path::new("broken.dbc"), text).unwrap_err();
        let RuntimeDbcError::Parse { line, .. } = &e else {
            panic!("{e:?}")
        };
        assert!(line.is_some(), "{e:?}");
        let msg = crate::error_chain::chain(&e);
        assert!(msg.starts_with("broken.dbc:"), "{msg}");
        let e = RuntimeDbc::load(Path::new("/nonexistent/x.dbc")).unwrap_err();
        assert!(crate::error_chain::chain(&e).contains("/nonexistent/x.dbc"));
    }

    #[test]
    fn layouts_the_decoder_cannot_hold_are_errors_naming_the_signal() {
        let text = "VERSION \"\"\nNS_ :\nBS_:\nBU_: A\nBO_ 1 M: 8 A\n SG_ X m1 : 0|8@1+ (1,0) [0|0] \"\" A\n";
        let e = RuntimeDbc::parse(Path::new("m.dbc"), text).unwrap_err();
        assert!(e.to_string().starts_with("m.dbc: M.X: multiplexed"), "{e}");
    }

    #[test]
    fn windows_1252_text_is_read() {
        let dir = std::env::temp_dir().join(format!("ddct-rtdbc-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("cp1252.dbc");
        let mut bytes = FOREIGN.replace("\"m/s\"", "\"\u{b0}C\"").into_bytes();
        // Replace the UTF-8 degree sign (C2 B0) by its Windows-1252 byte (B0).
        let at = bytes.windows(2).position(|w| w == [0xC2, 0xB0]).unwrap();
        bytes.remove(at);
        std::fs::write(&path, &bytes).unwrap();
        let db = RuntimeDbc::load(&path).unwrap();
        assert_eq!(db.message(1280, false).unwrap().signals[0].unit, "\u{b0}C");
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
