//! One decoded frame as `ddct log decode` writes it ([`Shown`]), from either decoder of a run
//! ([`AnyDecoder`]: the built-in contract or a DBC file given at run time).

use crate::can::candump::LogRecord;
use crate::can::decode::{DecodedFrame, Gap, LogDecoder};
use crate::can::runtime_dbc;
use std::time::Duration;

/// The E2E field of a frame whose verdict a `--dbc` decode does not compute.
const E2E_NOT_COMPUTED: &str = "n/a";

/// One decoded frame as the formats write it.
pub(crate) struct Shown<'a> {
    pub(crate) timestamp: Duration,
    pub(crate) iface: &'a str,
    pub(crate) id: u32,
    pub(crate) name: Option<&'a str>,
    /// The E2E verdict's name; `n/a` where a `--dbc` decode does not compute it.
    pub(crate) e2e: &'static str,
    pub(crate) signals: Vec<ShownSignal<'a>>,
    pub(crate) error: Option<String>,
}

pub(crate) struct ShownSignal<'a> {
    pub(crate) name: &'a str,
    pub(crate) value: f64,
    /// The value as the table shows it (a value-table name or the number at its resolution);
    /// formatted only for the table (empty for CSV and JSON, which print the value).
    pub(crate) text: String,
    pub(crate) label: Option<&'a str>,
    pub(crate) unit: &'a str,
    pub(crate) in_range: bool,
}

impl<'a> Shown<'a> {
    pub(crate) fn builtin(d: &'a DecodedFrame, with_text: bool) -> Self {
        Shown {
            timestamp: d.timestamp,
            iface: &d.iface,
            id: d.id,
            name: d.message.map(|m| m.name),
            e2e: d.e2e.as_str(),
            signals: d
                .signals
                .iter()
                .map(|s| ShownSignal {
                    name: s.signal.name,
                    value: s.value,
                    text: if with_text {
                        s.display_value()
                    } else {
                        String::new()
                    },
                    label: s.label,
                    unit: s.signal.unit,
                    in_range: s.in_range,
                })
                .collect(),
            error: d.error.as_ref().map(|e| e.to_string()),
        }
    }

    pub(crate) fn runtime(r: &'a LogRecord, d: &runtime_dbc::Decoded<'a>, with_text: bool) -> Self {
        Shown {
            timestamp: r.timestamp,
            iface: &r.iface,
            id: r.frame.raw_id(),
            name: d.message.map(|m| m.name.as_str()),
            e2e: d.e2e.map_or(E2E_NOT_COMPUTED, |v| v.as_str()),
            signals: d
                .signals
                .iter()
                .map(|s| ShownSignal {
                    name: &s.signal.name,
                    value: s.value,
                    text: if with_text {
                        s.display_value()
                    } else {
                        String::new()
                    },
                    label: s.label,
                    unit: &s.signal.unit,
                    in_range: s.in_range,
                })
                .collect(),
            error: d.issue.as_ref().map(|e| e.to_string()),
        }
    }
}

/// The decoder of a decode run: the built-in contract or a DBC file.
pub enum AnyDecoder<'a> {
    Builtin(LogDecoder),
    Runtime(runtime_dbc::Decoder<'a>),
}

impl<'a> AnyDecoder<'a> {
    /// The logger lost `frames` frames before the next one (none: nothing to tell).
    pub(crate) fn input_lost(&mut self, frames: u64) {
        match self {
            _ if frames == 0 => {}
            AnyDecoder::Builtin(d) => d.input_lost(frames),
            AnyDecoder::Runtime(d) => d.input_lost(frames),
        }
    }

    /// The silences found so far and the frames the logger reported lost.
    pub fn gaps_and_lost(&self) -> (&[Gap<'a>], u64) {
        match self {
            AnyDecoder::Builtin(dec) => (dec.gaps(), dec.frames_lost()),
            AnyDecoder::Runtime(dec) => (dec.gaps(), dec.frames_lost()),
        }
    }
}
