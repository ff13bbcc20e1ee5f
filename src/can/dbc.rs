//! The bus contract read from the DBC: the `can-dbc` crate parses the file (the grammar cantools
//! reads), and this module keeps the subset the contract uses — nodes, 11-bit messages of up to 8
//! bytes with plain (non-multiplexed) Intel signals, their comments, `GenMsgCycleTime` and value
//! tables — as plain structs for the code generator. Anything outside the subset is an error
//! naming its line, never silently dropped.
//!
//! `build.rs` includes this file to generate the message types (issue 15: the hand-written
//! parser of 250 lines it replaced is gone); the library compiles it too, so its tests run with
//! the others.

use std::fmt;

/// One signal of a message, as written in the DBC.
#[derive(Debug, Clone, PartialEq)]
pub struct DbcSignal {
    pub name: String,
    pub start_bit: u32,
    pub length: u32,
    /// `true` for Intel (little-endian, `@1`), the only byte order the contract uses.
    pub little_endian: bool,
    pub signed: bool,
    pub factor: f64,
    pub offset: f64,
    pub min: f64,
    pub max: f64,
    pub unit: String,
    pub receivers: Vec<String>,
    /// Value table (`VAL_`), raw value → label, in ascending raw order.
    pub values: Vec<(u64, String)>,
    pub comment: String,
}

/// One message of the DBC.
#[derive(Debug, Clone, PartialEq)]
pub struct DbcMessage {
    pub id: u32,
    pub name: String,
    pub dlc: u8,
    pub sender: String,
    pub signals: Vec<DbcSignal>,
    /// `GenMsgCycleTime` in ms, 0 when event-driven.
    pub cycle_ms: u32,
    pub comment: String,
}

/// The parsed database.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct DbcDatabase {
    pub nodes: Vec<String>,
    pub messages: Vec<DbcMessage>,
}

/// A parse error naming the line (1-based) and what is wrong.
#[derive(Debug, Clone, PartialEq)]
pub struct DbcParseError {
    pub line: usize,
    pub message: String,
}

impl fmt::Display for DbcParseError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "line {}: {}", self.line, self.message)
    }
}

impl std::error::Error for DbcParseError {}

/// An error of a contract DBC: the line (1-based; 0 when the whole file is meant) and what is
/// wrong.
fn err<T>(line: usize, message: impl Into<String>) -> Result<T, DbcParseError> {
    Err(DbcParseError {
        line,
        message: message.into(),
    })
}

/// The 1-based line of the first line at or after `from` whose words start with `words`
/// (`BO_ 256`, `SG_ EngSpeed`), else `from` (0 when not found at all).
fn line_of(text: &str, from: usize, words: &[&str]) -> usize {
    text.lines()
        .enumerate()
        .skip(from.saturating_sub(1))
        .find(|(_, l)| {
            let mut w = l
                .split(|c: char| c.is_whitespace() || c == ':')
                .filter(|w| !w.is_empty());
            words.iter().all(|x| w.next() == Some(*x))
        })
        .map_or(from, |(i, _)| i + 1)
}

fn number(v: &can_dbc::NumericValue) -> f64 {
    match *v {
        can_dbc::NumericValue::Uint(u) => u as f64,
        can_dbc::NumericValue::Int(i) => i as f64,
        can_dbc::NumericValue::Double(d) => d,
    }
}

/// Parses a contract DBC (the module documentation says which subset).
pub fn parse_dbc(text: &str) -> Result<DbcDatabase, DbcParseError> {
    let dbc = can_dbc::Dbc::try_from(text).or_else(|e| {
        let line = match &e {
            can_dbc::DbcError::Pest(p) => match p.line_col {
                pest::error::LineColLocation::Pos((l, _))
                | pest::error::LineColLocation::Span((l, _), _) => l,
            },
            _ => 0,
        };
        err(line, format!("not a DBC the contract reads: {e}"))
    })?;
    let mut db = DbcDatabase {
        nodes: dbc.nodes.iter().map(|n| n.0.clone()).collect(),
        messages: Vec::with_capacity(dbc.messages.len()),
    };
    for m in &dbc.messages {
        let message = convert_message(text, &dbc, m)?;
        if db
            .messages
            .iter()
            .any(|o| o.id == message.id || o.name == message.name)
        {
            let line = line_of(text, 1, &["BO_", &message.id.to_string()]);
            return err(
                line,
                format!("message {} (id {}) defined twice", message.name, message.id),
            );
        }
        db.messages.push(message);
    }
    for v in &dbc.value_descriptions {
        if let can_dbc::ValueDescription::Signal {
            message_id, name, ..
        } = v
        {
            if dbc.signal_by_name(*message_id, name).is_none() {
                return err(
                    0,
                    format!("VAL_ for unknown signal {name} of message {message_id:?}"),
                );
            }
        }
    }
    Ok(db)
}

/// One message of the contract, its signals checked against the subset.
fn convert_message(
    text: &str,
    dbc: &can_dbc::Dbc,
    m: &can_dbc::Message,
) -> Result<DbcMessage, DbcParseError> {
    let id = match m.id {
        can_dbc::MessageId::Standard(id) if id <= 0x7FF => u32::from(id),
        other => {
            let raw = match other {
                can_dbc::MessageId::Standard(id) => u32::from(id),
                // Written in the DBC with bit 31 set.
                can_dbc::MessageId::Extended(id) => id | 0x8000_0000,
            };
            return err(
                line_of(text, 1, &["BO_", &raw.to_string()]),
                format!("message {}: only 11-bit standard IDs are supported", m.name),
            );
        }
    };
    let line = line_of(text, 1, &["BO_", &id.to_string()]);
    let dlc = u8::try_from(m.size).ok().filter(|d| *d <= 8);
    let Some(dlc) = dlc else {
        return err(
            line,
            format!("message {}: DLC {} exceeds 8", m.name, m.size),
        );
    };
    let mut signals: Vec<DbcSignal> = Vec::with_capacity(m.signals.len());
    for s in &m.signals {
        let sig = convert_signal(dbc, m, s, dlc)
            .or_else(|e| err(line_of(text, line, &["SG_", &s.name]), e))?;
        if signals.iter().any(|o| o.name == sig.name) {
            let at = line_of(text, line, &["SG_", &s.name]);
            return err(at, format!("signal {} defined twice in {}", s.name, m.name));
        }
        signals.push(sig);
    }
    let cycle_ms = match dbc.message_attribute(m.id, "GenMsgCycleTime") {
        None => 0,
        Some(can_dbc::AttributeValue::Uint(u)) => u32::try_from(*u).unwrap_or(u32::MAX),
        Some(can_dbc::AttributeValue::Int(i)) => u32::try_from(*i).unwrap_or(0),
        Some(other) => {
            return err(
                line,
                format!(
                    "message {}: GenMsgCycleTime {other:?} is not a whole number of ms",
                    m.name
                ),
            )
        }
    };
    Ok(DbcMessage {
        id,
        name: m.name.clone(),
        dlc,
        sender: m
            .transmitter
            .clone()
            .unwrap_or_else(|| "Vector__XXX".into()),
        signals,
        cycle_ms,
        comment: dbc.message_comment(m.id).unwrap_or_default().to_string(),
    })
}

/// One signal of the contract: plain, Intel, inside the message's bytes, a finite non-zero
/// factor, min ≤ max; its value table (sorted by raw value) and comment.
fn convert_signal(
    dbc: &can_dbc::Dbc,
    m: &can_dbc::Message,
    s: &can_dbc::Signal,
    dlc: u8,
) -> Result<DbcSignal, String> {
    let name = &s.name;
    if s.multiplexer_indicator != can_dbc::MultiplexIndicator::Plain {
        return Err(format!(
            "signal {name}: multiplexed signals are not supported"
        ));
    }
    if s.byte_order != can_dbc::ByteOrder::LittleEndian {
        return Err(format!(
            "signal {name}: Motorola byte order is not part of the contract"
        ));
    }
    let (start_bit, length) = (s.start_bit, s.size);
    if length == 0 || length > 64 || start_bit + length > u64::from(dlc) * 8 {
        return Err(format!(
            "signal {name}: bits {start_bit}..{} do not fit DLC {dlc}",
            start_bit + length
        ));
    }
    let (min, max) = (number(&s.min), number(&s.max));
    if s.factor == 0.0 || !s.factor.is_finite() || !s.offset.is_finite() || min > max {
        return Err(format!("signal {name}: bad factor/offset/range"));
    }
    let mut values = Vec::new();
    for d in dbc
        .value_descriptions_for_signal(m.id, name)
        .unwrap_or_default()
    {
        let raw = u64::try_from(d.id)
            .map_err(|_| format!("signal {name}: negative raw value {}", d.id))?;
        values.push((raw, d.description.clone()));
    }
    values.sort_by_key(|p| p.0);
    Ok(DbcSignal {
        name: name.clone(),
        // Checked above: inside 64 bits.
        start_bit: start_bit as u32,
        length: length as u32,
        little_endian: true,
        signed: s.value_type == can_dbc::ValueType::Signed,
        factor: s.factor,
        offset: s.offset,
        min,
        max,
        unit: s.unit.clone(),
        receivers: s.receivers.clone(),
        values,
        comment: dbc
            .signal_comment(m.id, name)
            .unwrap_or_default()
            .to_string(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    const SMALL: &str = r#"VERSION ""
BU_: A B
BO_ 256 M1: 8 A
 SG_ S1 : 0|16@1+ (0.5,0) [0|100] "rpm" B
 SG_ S2 : 16|4@1- (1,0) [-8|7] "" B,A
CM_ SG_ 256 S1 "two
lines";
BA_ "GenMsgCycleTime" BO_ 256 10;
VAL_ 256 S2 0 "Zero" 1 "One" ;
"#;

    #[test]
    fn parses_subset() {
        let db = parse_dbc(SMALL).unwrap();
        assert_eq!(db.nodes, vec!["A", "B"]);
        let m = &db.messages[0];
        assert_eq!(
            (m.id, m.name.as_str(), m.dlc, m.cycle_ms),
            (256, "M1", 8, 10)
        );
        assert_eq!(m.signals[0].factor, 0.5);
        assert_eq!(m.signals[0].comment, "two\nlines");
        assert!(m.signals[1].signed);
        assert_eq!(m.signals[1].receivers, vec!["B", "A"]);
        assert_eq!(m.signals[1].values[1], (1, "One".to_string()));
    }

    #[test]
    fn errors_name_the_line() {
        let bad = "BU_: A\nBO_ 256 M1: 8 A\n SG_ S1 : 0|16@0+ (1,0) [0|1] \"\" A\n";
        let e = parse_dbc(bad).unwrap_err();
        assert_eq!(e.line, 3);
        assert!(e.message.contains("Motorola"), "{e}");
        let e = parse_dbc("BO_ 256 M1: 8 A\n SG_ S1 : 60|16@1+ (1,0) [0|1] \"\" A\n").unwrap_err();
        assert_eq!(e.line, 2);
        assert!(e.message.contains("do not fit"), "{e}");
        let e = parse_dbc("FOO bar\n").unwrap_err();
        assert_eq!(e.line, 1);
    }

    /// What the parser reads but the contract does not use is refused at its line: a
    /// multiplexed signal, an extended id.
    #[test]
    fn constructs_outside_the_subset_are_refused_at_their_line() {
        let mux = "BU_: A\nBO_ 256 M1: 8 A\n SG_ Sel M : 0|8@1+ (1,0) [0|1] \"\" A\n SG_ V m1 : 8|8@1+ (1,0) [0|1] \"\" A\n";
        let e = parse_dbc(mux).unwrap_err();
        assert_eq!(e.line, 3, "{e}");
        assert!(e.message.contains("multiplexed"), "{e}");
        let ext = "BU_: A\nBO_ 2147483904 M1: 8 A\n SG_ S : 0|8@1+ (1,0) [0|1] \"\" A\n";
        let e = parse_dbc(ext).unwrap_err();
        assert!(e.message.contains("11-bit"), "{e}");
        assert_eq!(e.line, 2, "{e}");
    }
}
