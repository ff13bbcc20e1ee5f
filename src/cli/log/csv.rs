//! `ddct log decode --format csv` with the built-in contract, on two threads: this one reads,
//! parses and decodes the log (the E2E and silence tracking go frame by frame, in order) into
//! blocks of decoded frames; a writer thread turns each block into CSV rows and writes them, in
//! the order they came.

use super::Decoding;
use anyhow::Context as _;
use ddct::can::candump::{LogError, LogReader};
use ddct::can::decode::LogDecoder;
use ddct::can::decode_csv::{CsvRows, DecodedBlock, CSV_HEADER};
use std::io::{Read, Write};
use std::sync::mpsc::{self, Receiver, Sender, SyncSender};

/// Frames per block from a file.
const BLOCK_FRAMES: usize = 2048;
/// Frames per block from standard input: a live pipe's rows are not held back much longer than
/// an 8 KiB output buffer holds them.
const BLOCK_FRAMES_STDIN: usize = 16;
/// Blocks on their way to the writer at most (the decoder waits beyond).
const BLOCKS_IN_FLIGHT: usize = 4;

/// Decodes the log of `reader` and writes its CSV (header included) to `out`.
pub(super) fn csv_builtin<R: Read>(
    reader: &mut LogReader<R>,
    dec: &mut LogDecoder,
    run: &mut Decoding<'_>,
    out: &mut (impl Write + Send),
) -> anyhow::Result<()> {
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
        let decoded = decode_blocks(reader, dec, run, frames_per_block, &to_writer, &spare);
        // The writer ends with the last block.
        drop(to_writer);
        let written = writer
            .join()
            .unwrap_or_else(|panic| std::panic::resume_unwind(panic));
        // A write error stops the decoder early: the write error is the one to report.
        written?;
        decoded
    })
}

/// Reads and decodes the log into blocks of `frames_per_block` frames sent to the writer; stops
/// early when the writer has stopped (its error says why).
fn decode_blocks<R: Read>(
    reader: &mut LogReader<R>,
    dec: &mut LogDecoder,
    run: &mut Decoding<'_>,
    frames_per_block: usize,
    to_writer: &SyncSender<DecodedBlock>,
    spare: &Receiver<DecodedBlock>,
) -> anyhow::Result<()> {
    let mut block = DecodedBlock::default();
    while let Some(item) = reader.next_ref() {
        let rec = match item {
            Ok(r) => r,
            Err(LogError::Line { line, kind }) => {
                run.bad_line(line, &kind);
                continue;
            }
            Err(e) => return Err(e).with_context(|| format!("{}", run.file.display())),
        };
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
            let next = spare.try_recv().unwrap_or_default();
            run.frames_read(block.frames_read);
            if to_writer.send(std::mem::replace(&mut block, next)).is_err() {
                return Ok(());
            }
        }
    }
    run.frames_read(block.frames_read);
    // An error of the writer is reported by it.
    let _ = to_writer.send(block);
    Ok(())
}

/// Writes the rows of every block received, handing the emptied blocks back for reuse.
fn write_blocks(
    blocks: &Receiver<DecodedBlock>,
    give_back: &Sender<DecodedBlock>,
    out: &mut impl Write,
) -> std::io::Result<()> {
    let mut rows = CsvRows::new();
    for mut block in blocks {
        rows.clear();
        rows.push_block(&block);
        out.write_all(rows.text())?;
        block.clear();
        // The decoder may be done with blocks.
        let _ = give_back.send(block);
    }
    Ok(())
}
