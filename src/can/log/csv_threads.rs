//! `ddct log decode --format csv` with the built-in contract, on two threads: this one reads,
//! parses and decodes the log (the E2E and silence tracking go frame by frame, in order) into
//! blocks of decoded frames; a writer thread turns each block into CSV rows and writes them, in
//! the order they came. When the writer falls behind, this thread writes a block's rows itself
//! and hands the writer the text: both threads share the formatting, the heavier half.

use super::error::DecodeError;
use super::tally::Tally;
use crate::can::candump::LogReader;
use crate::can::decode::LogDecoder;
use crate::can::decode_csv::{CsvRows, DecodedBlock, CSV_HEADER};
use std::io::{Read, Write};
use std::sync::mpsc::{self, Receiver, Sender, SyncSender, TrySendError};

/// Frames per block from a file.
const BLOCK_FRAMES: usize = 2048;
/// Frames per block from standard input: a live pipe's rows are not held back much longer than
/// an 8 KiB output buffer holds them.
const BLOCK_FRAMES_STDIN: usize = 16;
/// Blocks on their way to the writer at most; beyond, the decoder writes the rows itself.
const BLOCKS_IN_FLIGHT: usize = 2;

/// A block for the writer: decoded frames, or their rows already written.
enum Block {
    Decoded(DecodedBlock),
    Rows(Vec<u8>),
}

/// Decodes the log of `reader` and writes its CSV (header included) to `out`.
pub(crate) fn csv_builtin<R: Read>(
    reader: &mut LogReader<R>,
    dec: &mut LogDecoder,
    run: &mut Tally<'_>,
    out: &mut (impl Write + Send),
) -> Result<(), DecodeError> {
    out.write_all(CSV_HEADER.as_bytes())?;
    let frames_per_block = if run.per_frame {
        BLOCK_FRAMES_STDIN
    } else {
        BLOCK_FRAMES
    };
    std::thread::scope(|scope| {
        let (to_writer, blocks) = mpsc::sync_channel(BLOCKS_IN_FLIGHT);
        let (give_back, spare) = mpsc::channel();
        let writer = scope.spawn(move || write_blocks(&blocks, &give_back, out));
        let mut blocks = BlockSender {
            to_writer,
            spare,
            rows: CsvRows::new(),
            blocks: Vec::new(),
            texts: Vec::new(),
        };
        let decoded = decode_blocks(reader, dec, run, frames_per_block, &mut blocks);
        // The writer ends with the last block.
        drop(blocks);
        let written = writer
            .join()
            .unwrap_or_else(|panic| std::panic::resume_unwind(panic));
        // A write error stops the decoder early: the write error is the one to report.
        written?;
        decoded
    })
}

/// Reads and decodes the log into blocks of `frames_per_block` frames for the writer; stops
/// early when the writer has stopped (its error says why).
fn decode_blocks<R: Read>(
    reader: &mut LogReader<R>,
    dec: &mut LogDecoder,
    run: &mut Tally<'_>,
    frames_per_block: usize,
    blocks: &mut BlockSender,
) -> Result<(), DecodeError> {
    let mut block = DecodedBlock::default();
    while let Some(item) = reader.next_ref() {
        let Some(rec) = run.record(item)? else {
            continue;
        };
        dec.input_lost(std::mem::take(&mut run.lost_pending));
        block.frames_read += 1;
        // Every frame goes through the decoder (its E2E and gap tracking); only the selected
        // ones are turned into rows.
        let found = dec.track(rec.timestamp, &rec.frame);
        if !run.wanted(rec.frame.raw_id()) {
            continue;
        }
        run.verdict(found.e2e.as_str());
        block.push(rec.timestamp, rec.iface, &rec.frame, &found);
        if block.len() >= frames_per_block {
            run.frames_read(block.frames_read);
            if !blocks.send(&mut block) {
                return Ok(());
            }
        }
    }
    run.frames_read(block.frames_read);
    // An error of the writer is reported by it.
    blocks.send(&mut block);
    Ok(())
}

/// The decoder's end of the way to the writer.
struct BlockSender {
    to_writer: SyncSender<Block>,
    /// Blocks and texts the writer is done with.
    spare: Receiver<Block>,
    rows: CsvRows,
    /// Those received, for reuse (their memory stays mapped: no page faults for new ones).
    blocks: Vec<DecodedBlock>,
    texts: Vec<Vec<u8>>,
}

impl BlockSender {
    /// Sends `block` to the writer (as rows written here when the writer is behind) and leaves
    /// an empty one in its place; false when the writer has stopped.
    fn send(&mut self, block: &mut DecodedBlock) -> bool {
        for spare in self.spare.try_iter() {
            match spare {
                Block::Decoded(b) => self.blocks.push(b),
                Block::Rows(t) => self.texts.push(t),
            }
        }
        let empty = self.blocks.pop().unwrap_or_default();
        match self
            .to_writer
            .try_send(Block::Decoded(std::mem::replace(block, empty)))
        {
            Ok(()) => true,
            Err(TrySendError::Full(Block::Decoded(mut full))) => {
                self.rows.push_block(&full);
                full.clear();
                self.blocks.push(std::mem::replace(block, full));
                let rows = self.rows.take_text(self.texts.pop().unwrap_or_default());
                self.to_writer.send(Block::Rows(rows)).is_ok()
            }
            Err(_) => false,
        }
    }
}

/// Writes the rows of every block received, handing the emptied blocks back for reuse.
fn write_blocks(
    blocks: &Receiver<Block>,
    give_back: &Sender<Block>,
    out: &mut impl Write,
) -> std::io::Result<()> {
    let mut rows = CsvRows::new();
    for block in blocks {
        let spare = match block {
            Block::Decoded(mut decoded) => {
                rows.clear();
                rows.push_block(&decoded);
                out.write_all(rows.text())?;
                decoded.clear();
                Block::Decoded(decoded)
            }
            Block::Rows(text) => {
                out.write_all(&text)?;
                Block::Rows(text)
            }
        };
        // The decoder may be done with blocks.
        let _ = give_back.send(spare);
    }
    Ok(())
}
