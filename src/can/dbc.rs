//! A parser for the subset of the DBC format the ddct bus contract uses: nodes (`BU_`), messages
//! (`BO_`) with plain (non-multiplexed) signals (`SG_`), comments (`CM_`), attributes (`BA_`, of
//! which `GenMsgCycleTime` is kept) and value tables (`VAL_`).
//!
//! Std-only on purpose: `build.rs` includes this file to generate the message types, and the
//! library uses it to report DBC errors with a line number. Anything outside the subset is an
//! error naming the line, never silently ignored.

use std::collections::BTreeMap;
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

fn err<T>(line: usize, message: impl Into<String>) -> Result<T, DbcParseError> {
    Err(DbcParseError {
        line,
        message: message.into(),
    })
}

/// Splits `text` into statements: (first line number, statement text). A statement ends at the
/// end of a line unless a quoted string is still open (comments may span lines).
fn statements(text: &str) -> Vec<(usize, String)> {
    let mut out = Vec::new();
    let mut current = String::new();
    let mut start_line = 0;
    let mut in_quote = false;
    for (i, line) in text.lines().enumerate() {
        if current.is_empty() {
            start_line = i + 1;
        } else {
            current.push('\n');
        }
        let mut escaped = false;
        for c in line.chars() {
            if escaped {
                escaped = false;
            } else if c == '\\' && in_quote {
                escaped = true;
            } else if c == '"' {
                in_quote = !in_quote;
            }
        }
        current.push_str(line);
        if !in_quote {
            let trimmed = current.trim().to_string();
            if !trimmed.is_empty() {
                out.push((start_line, trimmed));
            }
            current.clear();
        }
    }
    if !current.trim().is_empty() {
        out.push((start_line, current.trim().to_string()));
    }
    out
}

/// Tokens of one statement: quoted strings keep their quotes stripped and are marked.
#[derive(Debug, Clone, PartialEq)]
enum Tok {
    Word(String),
    Str(String),
    Punct(char),
}

fn tokenize(line_no: usize, s: &str) -> Result<Vec<Tok>, DbcParseError> {
    let mut toks = Vec::new();
    let chars: Vec<char> = s.chars().collect();
    let mut i = 0;
    while i < chars.len() {
        let c = chars[i];
        if c.is_whitespace() {
            i += 1;
        } else if c == '"' {
            let mut j = i + 1;
            let mut text = String::new();
            while j < chars.len() && chars[j] != '"' {
                if chars[j] == '\\' && j + 1 < chars.len() {
                    j += 1;
                }
                text.push(chars[j]);
                j += 1;
            }
            if j >= chars.len() {
                return err(line_no, "unterminated string");
            }
            toks.push(Tok::Str(text));
            i = j + 1;
        } else if matches!(c, ':' | '|' | '@' | '(' | ')' | ',' | '[' | ']' | ';') {
            toks.push(Tok::Punct(c));
            i += 1;
        } else {
            let mut j = i;
            // A word or number; '+'/'-' belong to numbers and to the `@1+` sign marker.
            while j < chars.len()
                && !chars[j].is_whitespace()
                && !matches!(
                    chars[j],
                    ':' | '|' | '@' | '(' | ')' | ',' | '[' | ']' | ';' | '"'
                )
            {
                j += 1;
            }
            toks.push(Tok::Word(chars[i..j].iter().collect()));
            i = j;
        }
    }
    Ok(toks)
}

struct Cursor<'a> {
    toks: &'a [Tok],
    pos: usize,
    line: usize,
}

impl<'a> Cursor<'a> {
    fn word(&mut self, what: &str) -> Result<String, DbcParseError> {
        match self.toks.get(self.pos) {
            Some(Tok::Word(w)) => {
                self.pos += 1;
                Ok(w.clone())
            }
            other => err(self.line, format!("expected {what}, found {other:?}")),
        }
    }
    fn string(&mut self, what: &str) -> Result<String, DbcParseError> {
        match self.toks.get(self.pos) {
            Some(Tok::Str(w)) => {
                self.pos += 1;
                Ok(w.clone())
            }
            other => err(
                self.line,
                format!("expected {what} (a quoted string), found {other:?}"),
            ),
        }
    }
    fn punct(&mut self, c: char) -> Result<(), DbcParseError> {
        match self.toks.get(self.pos) {
            Some(Tok::Punct(p)) if *p == c => {
                self.pos += 1;
                Ok(())
            }
            other => err(self.line, format!("expected '{c}', found {other:?}")),
        }
    }
    fn peek_punct(&self, c: char) -> bool {
        matches!(self.toks.get(self.pos), Some(Tok::Punct(p)) if *p == c)
    }
    fn number<T: std::str::FromStr>(&mut self, what: &str) -> Result<T, DbcParseError> {
        let w = self.word(what)?;
        w.parse::<T>()
            .or_else(|_| err(self.line, format!("{what}: '{w}' is not a valid number")))
    }
    fn done(&self) -> bool {
        self.pos >= self.toks.len()
    }
}

/// Parses the DBC subset described in the module documentation.
pub fn parse_dbc(text: &str) -> Result<DbcDatabase, DbcParseError> {
    let mut db = DbcDatabase::default();
    let mut cycle: BTreeMap<u32, u32> = BTreeMap::new();
    let mut msg_comments: BTreeMap<u32, String> = BTreeMap::new();
    let mut sig_comments: BTreeMap<(u32, String), String> = BTreeMap::new();
    let mut values: BTreeMap<(u32, String), Vec<(u64, String)>> = BTreeMap::new();
    // Which message a SG_ line belongs to.
    let mut current_msg: Option<usize> = None;

    for (line, stmt) in statements(text) {
        let keyword = stmt.split_whitespace().next().unwrap_or("");
        match keyword {
            "VERSION" | "NS_" | "BS_:" | "BS_" | "BA_DEF_" | "BA_DEF_DEF_" | "NS_:" => {
                current_msg = None;
            }
            // Indented NS_ entries (symbol names) are single words.
            k if k.ends_with('_') && stmt.split_whitespace().count() == 1 => {}
            "BU_:" | "BU_" => {
                current_msg = None;
                let rest = stmt.trim_start_matches("BU_").trim_start_matches(':');
                db.nodes = rest.split_whitespace().map(str::to_string).collect();
            }
            "BO_" => {
                let toks = tokenize(line, &stmt)?;
                let mut c = Cursor {
                    toks: &toks,
                    pos: 1,
                    line,
                };
                let id: u32 = c.number("message id")?;
                let name = c.word("message name")?;
                c.punct(':')?;
                let dlc: u8 = c.number("message DLC")?;
                let sender = c.word("message sender")?;
                if !c.done() {
                    return err(line, "trailing tokens after BO_");
                }
                if id & 0x8000_0000 != 0 || id > 0x7FF {
                    return err(
                        line,
                        format!("message {name}: only 11-bit standard IDs are supported, got {id}"),
                    );
                }
                if dlc > 8 {
                    return err(line, format!("message {name}: DLC {dlc} exceeds 8"));
                }
                if db.messages.iter().any(|m| m.id == id || m.name == name) {
                    return err(line, format!("message {name} (id {id}) defined twice"));
                }
                db.messages.push(DbcMessage {
                    id,
                    name,
                    dlc,
                    sender,
                    signals: Vec::new(),
                    cycle_ms: 0,
                    comment: String::new(),
                });
                current_msg = Some(db.messages.len() - 1);
            }
            "SG_" => {
                let Some(mi) = current_msg else {
                    return err(line, "SG_ outside of a BO_ block");
                };
                let toks = tokenize(line, &stmt)?;
                let mut c = Cursor {
                    toks: &toks,
                    pos: 1,
                    line,
                };
                let name = c.word("signal name")?;
                if !c.peek_punct(':') {
                    return err(
                        line,
                        format!("signal {name}: multiplexed signals are not supported"),
                    );
                }
                c.punct(':')?;
                let start_bit: u32 = c.number("start bit")?;
                c.punct('|')?;
                let length: u32 = c.number("length")?;
                c.punct('@')?;
                let order_sign = c.word("byte order and sign")?;
                let (little_endian, signed) = match order_sign.as_str() {
                    "1+" => (true, false),
                    "1-" => (true, true),
                    "0+" | "0-" => {
                        return err(
                            line,
                            format!(
                                "signal {name}: Motorola byte order is not part of the contract"
                            ),
                        )
                    }
                    other => {
                        return err(
                            line,
                            format!("signal {name}: bad byte order/sign '{other}'"),
                        )
                    }
                };
                c.punct('(')?;
                let factor: f64 = c.number("factor")?;
                c.punct(',')?;
                let offset: f64 = c.number("offset")?;
                c.punct(')')?;
                c.punct('[')?;
                let min: f64 = c.number("minimum")?;
                c.punct('|')?;
                let max: f64 = c.number("maximum")?;
                c.punct(']')?;
                let unit = c.string("unit")?;
                let mut receivers = vec![c.word("receiver")?];
                while c.peek_punct(',') {
                    c.punct(',')?;
                    receivers.push(c.word("receiver")?);
                }
                if !c.done() {
                    return err(line, format!("signal {name}: trailing tokens"));
                }
                let msg = &mut db.messages[mi];
                if length == 0 || length > 64 || start_bit + length > u32::from(msg.dlc) * 8 {
                    return err(
                        line,
                        format!(
                            "signal {name}: bits {start_bit}..{} do not fit DLC {}",
                            start_bit + length,
                            msg.dlc
                        ),
                    );
                }
                if factor == 0.0 || !factor.is_finite() || !offset.is_finite() || min > max {
                    return err(line, format!("signal {name}: bad factor/offset/range"));
                }
                if msg.signals.iter().any(|s| s.name == name) {
                    return err(line, format!("signal {name} defined twice in {}", msg.name));
                }
                msg.signals.push(DbcSignal {
                    name,
                    start_bit,
                    length,
                    little_endian,
                    signed,
                    factor,
                    offset,
                    min,
                    max,
                    unit,
                    receivers,
                    values: Vec::new(),
                    comment: String::new(),
                });
            }
            "CM_" => {
                current_msg = None;
                let toks = tokenize(line, &stmt)?;
                let mut c = Cursor {
                    toks: &toks,
                    pos: 1,
                    line,
                };
                match toks.get(1) {
                    Some(Tok::Word(w)) if w == "BO_" => {
                        c.pos = 2;
                        let id: u32 = c.number("message id")?;
                        let text = c.string("comment")?;
                        msg_comments.insert(id, text);
                    }
                    Some(Tok::Word(w)) if w == "SG_" => {
                        c.pos = 2;
                        let id: u32 = c.number("message id")?;
                        let sig = c.word("signal name")?;
                        let text = c.string("comment")?;
                        sig_comments.insert((id, sig), text);
                    }
                    _ => {} // database and node comments are kept in the file only
                }
            }
            "BA_" => {
                current_msg = None;
                let toks = tokenize(line, &stmt)?;
                let mut c = Cursor {
                    toks: &toks,
                    pos: 1,
                    line,
                };
                let attr = c.string("attribute name")?;
                if attr == "GenMsgCycleTime" {
                    let kind = c.word("object kind")?;
                    if kind != "BO_" {
                        return err(line, "GenMsgCycleTime must be set on a BO_");
                    }
                    let id: u32 = c.number("message id")?;
                    let ms: u32 = c.number("cycle time")?;
                    cycle.insert(id, ms);
                }
            }
            "VAL_" => {
                current_msg = None;
                let toks = tokenize(line, &stmt)?;
                let mut c = Cursor {
                    toks: &toks,
                    pos: 1,
                    line,
                };
                let id: u32 = c.number("message id")?;
                let sig = c.word("signal name")?;
                let mut pairs = Vec::new();
                while !c.peek_punct(';') {
                    if c.done() {
                        return err(line, "VAL_ without terminating ';'");
                    }
                    let raw: u64 = c.number("raw value")?;
                    let label = c.string("value label")?;
                    pairs.push((raw, label));
                }
                pairs.sort_by_key(|p| p.0);
                values.insert((id, sig), pairs);
            }
            "" => {}
            other => {
                if current_msg.is_some() && other.starts_with("SG_") {
                    return err(line, "malformed SG_ line");
                }
                return err(line, format!("unsupported DBC statement '{other}'"));
            }
        }
    }

    for m in &mut db.messages {
        m.cycle_ms = cycle.remove(&m.id).unwrap_or(0);
        m.comment = msg_comments.remove(&m.id).unwrap_or_default();
        for s in &mut m.signals {
            s.comment = sig_comments
                .remove(&(m.id, s.name.clone()))
                .unwrap_or_default();
            s.values = values.remove(&(m.id, s.name.clone())).unwrap_or_default();
        }
    }
    if let Some((id, _)) = cycle.into_iter().next() {
        return err(0, format!("GenMsgCycleTime for unknown message id {id}"));
    }
    if let Some(((id, sig), _)) = values.into_iter().next() {
        return err(
            0,
            format!("VAL_ for unknown signal {sig} of message id {id}"),
        );
    }
    Ok(db)
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
}
