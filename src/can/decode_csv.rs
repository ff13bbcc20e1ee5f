//! The rows of `ddct log decode --format csv`, one per signal of a frame
//! (`time_s,iface,id,message,signal,value,unit,e2e`), appended to one byte buffer that the caller
//! writes out in large blocks: hundreds of thousands of frames a second, no allocation per frame
//! and no `core::fmt` but for rare numbers (see [`crate::num_text`]).

use super::codec::MessageDef;
use super::decode::FrameFound;
use super::frame::CanFrame;
use crate::num_text::{push_f64, push_hex_id, push_secs_micros};
use std::ops::Range;
use std::time::Duration;

/// The CSV's header line.
pub(crate) const CSV_HEADER: &str = "time_s,iface,id,message,signal,value,unit,e2e\n";

/// The columns of a frame shared by its rows.
#[derive(Debug, Clone, Copy)]
pub(crate) struct CsvFrame<'a> {
    pub timestamp: Duration,
    pub iface: &'a str,
    pub id: u32,
    /// Empty for a frame of no known message.
    pub message: &'a str,
    pub e2e: &'a str,
}

/// One signal's columns.
#[derive(Debug, Clone, Copy)]
pub(crate) struct CsvSignal<'a> {
    pub name: &'a str,
    pub value: f64,
    pub unit: &'a str,
}

/// Rows of CSV text, appended frame by frame.
#[derive(Debug, Default)]
pub(crate) struct CsvRows {
    text: Vec<u8>,
    /// The time column of the frame before and its text: frames of one cycle share it.
    time: Option<Duration>,
    time_text: Vec<u8>,
}

impl CsvRows {
    pub fn new() -> Self {
        Self::default()
    }

    /// The rows appended since [`CsvRows::clear`].
    pub fn text(&self) -> &[u8] {
        &self.text
    }

    pub fn clear(&mut self) {
        self.text.clear();
    }

    /// The rows appended since [`CsvRows::clear`], handed over; the next go into `buffer`
    /// (emptied first: a buffer handed over before, for reuse).
    pub fn take_text(&mut self, mut buffer: Vec<u8>) -> Vec<u8> {
        buffer.clear();
        std::mem::replace(&mut self.text, buffer)
    }

    /// Appends a frame's rows, one per signal; a frame with none has one row with the signal,
    /// value and unit empty.
    pub fn push_frame<'s>(
        &mut self,
        frame: &CsvFrame<'_>,
        signals: impl IntoIterator<Item = CsvSignal<'s>>,
    ) {
        let start = self.text.len();
        self.push_time(frame.timestamp);
        self.text.push(b',');
        self.text.extend_from_slice(frame.iface.as_bytes());
        self.text.push(b',');
        push_hex_id(&mut self.text, frame.id);
        self.text.push(b',');
        self.text.extend_from_slice(frame.message.as_bytes());
        self.text.push(b',');
        let prefix = start..self.text.len();
        let mut rows = 0;
        for s in signals {
            if rows > 0 {
                self.text.extend_from_within(prefix.clone());
            }
            self.text.extend_from_slice(s.name.as_bytes());
            self.text.push(b',');
            push_f64(&mut self.text, s.value);
            self.text.push(b',');
            self.text.extend_from_slice(s.unit.as_bytes());
            self.push_end(frame.e2e);
            rows += 1;
        }
        if rows == 0 {
            self.text.extend_from_slice(b",,");
            self.push_end(frame.e2e);
        }
    }

    /// `,e2e` and the line end.
    fn push_end(&mut self, e2e: &str) {
        self.text.push(b',');
        self.text.extend_from_slice(e2e.as_bytes());
        self.text.push(b'\n');
    }

    /// The time column (`{:.6}` of the seconds), its text reused while the time stays.
    fn push_time(&mut self, t: Duration) {
        if self.time != Some(t) {
            self.time_text.clear();
            push_secs_micros(&mut self.time_text, t);
            self.time = Some(t);
        }
        self.text.extend_from_slice(&self.time_text);
    }
}

/// Frames decoded with the contract, on their way to [`CsvRows::push_block`] (on another
/// thread than the decoder's): each frame's columns, its signal values in the message's order,
/// and no text borrowed from the log.
#[derive(Debug, Default)]
pub struct DecodedBlock {
    frames: Vec<BlockFrame>,
    values: Vec<f64>,
    /// The frames' interface names, each written once while it stays the same.
    ifaces: String,
    /// Frames read for this block: those in it and those `-m` left out.
    pub frames_read: u64,
}

#[derive(Debug, Clone)]
struct BlockFrame {
    timestamp: Duration,
    iface: Range<usize>,
    id: u32,
    message: Option<&'static MessageDef>,
    e2e: &'static str,
    /// The frame's signal values in `values` (none for a payload of the wrong length).
    values: Range<usize>,
}

impl DecodedBlock {
    /// Adds a frame seen at `timestamp` on `iface`, with what
    /// [`super::decode::LogDecoder::track`] found in it; decodes its signals' values.
    pub fn push(&mut self, timestamp: Duration, iface: &str, frame: &CanFrame, found: &FrameFound) {
        let iface = match self.frames.last() {
            Some(f) if &self.ifaces[f.iface.clone()] == iface => f.iface.clone(),
            _ => {
                self.ifaces.push_str(iface);
                self.ifaces.len() - iface.len()..self.ifaces.len()
            }
        };
        let start = self.values.len();
        if let Some(def) = found.message {
            // A payload of the wrong length has no values.
            let _ = def.values_into(frame.bytes(), &mut self.values);
        }
        self.frames.push(BlockFrame {
            timestamp,
            iface,
            id: frame.raw_id(),
            message: found.message,
            e2e: found.e2e.as_str(),
            values: start..self.values.len(),
        });
    }

    /// The frames in the block.
    pub fn len(&self) -> usize {
        self.frames.len()
    }

    pub fn is_empty(&self) -> bool {
        self.frames.is_empty()
    }

    /// Empties the block for reuse.
    pub fn clear(&mut self) {
        self.frames.clear();
        self.values.clear();
        self.ifaces.clear();
        self.frames_read = 0;
    }
}

impl CsvRows {
    /// Appends the rows of every frame of `block`.
    pub fn push_block(&mut self, block: &DecodedBlock) {
        for f in &block.frames {
            let frame = CsvFrame {
                timestamp: f.timestamp,
                iface: &block.ifaces[f.iface.clone()],
                id: f.id,
                message: f.message.map_or("", |m| m.name),
                e2e: f.e2e,
            };
            let defs = f.message.map_or(&[][..], |m| m.signals);
            let signals = defs.iter().zip(&block.values[f.values.clone()]);
            self.push_frame(
                &frame,
                signals.map(|(def, value)| CsvSignal {
                    name: def.name,
                    value: *value,
                    unit: def.unit,
                }),
            );
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn frame(t_us: u64, message: &str) -> CsvFrame<'_> {
        CsvFrame {
            timestamp: Duration::from_micros(t_us),
            iface: "vcan0",
            id: 0x130,
            message,
            e2e: "ok",
        }
    }

    #[test]
    fn one_row_per_signal_with_the_frame_columns() {
        let mut rows = CsvRows::new();
        let sig = |name, value, unit| CsvSignal { name, value, unit };
        rows.push_frame(
            &frame(1_795_664_797_622_242, "DCT_Sensors"),
            [sig("InShaft1Speed", 0.5, "rpm"), sig("Crc", 8.0, "")],
        );
        rows.push_frame(
            &frame(1_795_664_797_622_242, "DCT_Sensors"),
            [sig("T", -0.0, "degC")],
        );
        rows.push_frame(&frame(1_000_001, ""), []);
        let want = "1795664797.622242,vcan0,0x130,DCT_Sensors,InShaft1Speed,0.5,rpm,ok\n\
                    1795664797.622242,vcan0,0x130,DCT_Sensors,Crc,8,,ok\n\
                    1795664797.622242,vcan0,0x130,DCT_Sensors,T,-0,degC,ok\n\
                    1.000001,vcan0,0x130,,,,,ok\n";
        assert_eq!(String::from_utf8_lossy(rows.text()), want);
        let taken = rows.take_text(b"old".to_vec());
        assert_eq!(String::from_utf8_lossy(&taken), want);
        assert!(rows.text().is_empty());
        rows.push_frame(&frame(1_000_001, ""), []);
        rows.clear();
        assert!(rows.text().is_empty());
    }

    /// A block's rows are those of its frames decoded and written one by one.
    #[test]
    fn a_block_writes_the_rows_of_its_frames() {
        use crate::can::candump::LogRecord;
        use crate::can::decode::LogDecoder;
        use crate::can::e2e::sample_frames;
        use crate::can::CanFrame;
        let mut frames: Vec<CanFrame> = sample_frames()
            .iter()
            .map(|f| CanFrame::standard(f.def.id, &f.data).unwrap())
            .collect();
        frames.push(CanFrame::standard(0x7FF, &[1]).unwrap());
        frames.push(CanFrame::standard(0x100, &[1, 2]).unwrap());
        frames.push(CanFrame::extended(0x100, &[]).unwrap());
        let (mut block, mut one_by_one) = (DecodedBlock::default(), CsvRows::new());
        let (mut dec, mut dec_again) = (LogDecoder::default(), LogDecoder::default());
        for (k, frame) in frames.iter().enumerate() {
            let t = Duration::from_micros(1_000_000 + 10_000 * k as u64 / 3);
            let iface = if k % 5 == 4 { "can1" } else { "vcan0" };
            block.push(t, iface, frame, &dec.track(t, frame));
            let d = dec_again.decode(&LogRecord {
                timestamp: t,
                iface: iface.into(),
                frame: *frame,
                direction: None,
            });
            let shown = CsvFrame {
                timestamp: t,
                iface,
                id: d.id,
                message: d.message.map_or("", |m| m.name),
                e2e: d.e2e.as_str(),
            };
            one_by_one.push_frame(
                &shown,
                d.signals.iter().map(|s| CsvSignal {
                    name: s.signal.name,
                    value: s.value,
                    unit: s.signal.unit,
                }),
            );
        }
        assert_eq!(block.len(), frames.len());
        let mut rows = CsvRows::new();
        rows.push_block(&block);
        assert_eq!(
            String::from_utf8_lossy(rows.text()),
            String::from_utf8_lossy(one_by_one.text())
        );
        block.clear();
        assert!(block.is_empty());
    }
}
