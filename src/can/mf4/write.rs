//! Writing frames as an MDF 4.1 bus-logging file: records are kept per interface and frame kind
//! (25 bytes per data frame) and written at [`Mf4Writer::finish`] as one sorted data group each
//! (identification, header, file history, then per group DG → CG → SI and the channels, then
//! the `DT` blocks).

use super::block::{block_header, Builder, ID_BLOCK_LEN, MAGIC};
use super::error::Mf4Error;
use super::layout::{
    FrameKind, Member, BUS_CHANNEL, DATA_BYTES, DATA_DIR, DATA_LENGTH, DLC, DT_BYTES, DT_FLOAT_LE,
    ID, IDE, ID_IDE_BIT, REMOTE_DIR, TIME_BYTES,
};
use crate::can::candump::{Direction, LogRecord};
use embedded_can::Frame as _;
use std::io::Write;
use std::time::Duration;

/// Channel group flags: bus event, plain bus event (MDF 4.1 cg_flags bits 1 and 2).
const CG_BUS_EVENT: u16 = 0b110;
/// Channel flag: bus event (cn_flags bit 10).
const CN_BUS_EVENT: u32 = 1 << 10;
/// Source type BUS and bus type CAN (si_type, si_bus_type).
const SI_BUS: u8 = 2;
const SI_CAN: u8 = 2;
/// Channel types and sync type (cn_type, cn_sync_type).
const CN_FIXED: u8 = 0;
const CN_MASTER: u8 = 2;
const SYNC_TIME: u8 = 1;

/// The records of one interface and frame kind.
#[derive(Debug)]
struct Group {
    iface: String,
    kind: FrameKind,
    records: Vec<u8>,
    count: u64,
    /// Some record carries a direction (the `Dir` member is declared).
    directions: bool,
}

/// Collects frames and writes them as an MF4 file.
#[derive(Debug, Default)]
pub struct Mf4Writer {
    groups: Vec<Group>,
    /// The first frame's time: the header's start time; records hold the time since it.
    start: Option<Duration>,
    /// Interfaces in the order first seen (bus channel = index + 1).
    ifaces: Vec<String>,
}

impl Mf4Writer {
    pub fn new() -> Self {
        Self::default()
    }

    /// Frames pushed so far.
    pub fn frames(&self) -> u64 {
        self.groups.iter().map(|g| g.count).sum()
    }

    /// Adds one frame.
    pub fn push(&mut self, r: &LogRecord) {
        let start = *self.start.get_or_insert(r.timestamp);
        let kind = if r.frame.is_remote_frame() {
            FrameKind::Remote
        } else {
            FrameKind::Data
        };
        let bus = self.bus_channel(&r.iface);
        let i = match self
            .groups
            .iter()
            .position(|g| g.iface == r.iface && g.kind == kind)
        {
            Some(i) => i,
            None => {
                self.groups.push(Group {
                    iface: r.iface.clone(),
                    kind,
                    records: Vec::new(),
                    count: 0,
                    directions: false,
                });
                self.groups.len() - 1
            }
        };
        let g = &mut self.groups[i];
        g.directions |= r.direction.is_some();
        g.records
            .extend_from_slice(&record(r, start, bus, kind)[..kind.record_len()]);
        g.count += 1;
    }

    /// The bus channel number of an interface: 1 for the first interface seen, 2 for the next,
    /// … (the interfaces are kept in the order first seen; a handful, so a list).
    fn bus_channel(&mut self, iface: &str) -> u8 {
        let i = match self.ifaces.iter().position(|i| i == iface) {
            Some(i) => i,
            None => {
                self.ifaces.push(iface.to_string());
                self.ifaces.len() - 1
            }
        };
        (i + 1) as u8
    }

    /// Writes the file; the number of frames written.
    pub fn finish(mut self, mut out: impl Write) -> Result<u64, Mf4Error> {
        self.groups
            .sort_by(|a, b| (&a.iface, a.kind).cmp(&(&b.iface, b.kind)));
        let start_ns = self.start.map_or(0, |s| s.as_nanos() as u64);
        let mut b = Builder::default();
        b.buf.extend_from_slice(&id_block());
        let hd = b.add(b"HD", &[0; 6], &hd_data(start_ns));
        let fh_comment = b.xml(&format!(
            "<FHcomment><TX>written by ddct</TX><tool_id>ddct</tool_id>\
             <tool_vendor>ddct</tool_vendor><tool_version>{}</tool_version></FHcomment>",
            env!("CARGO_PKG_VERSION")
        ));
        let fh = b.add(b"FH", &[0, fh_comment], &fh_data(start_ns));
        b.set_link(hd, 1, fh);
        let mut dgs = Vec::new();
        for g in &self.groups {
            dgs.push(group_blocks(&mut b, g));
        }
        for (prev, next) in dgs.iter().zip(dgs.iter().skip(1)) {
            b.set_link(*prev, 0, *next);
        }
        if let Some(first) = dgs.first() {
            b.set_link(hd, 0, *first);
        }
        // The DT blocks follow the metadata, in group order.
        let mut at = b.buf.len() as u64;
        for (dg, g) in dgs.iter().zip(&self.groups) {
            b.set_link(*dg, 2, at);
            at += (block_header(b"DT", 0, 0).len() + g.records.len()).next_multiple_of(8) as u64;
        }
        out.write_all(&b.buf).map_err(io)?;
        for g in &self.groups {
            out.write_all(&block_header(b"DT", 0, g.records.len() as u64))
                .map_err(io)?;
            out.write_all(&g.records).map_err(io)?;
            let pad = g.records.len().next_multiple_of(8) - g.records.len();
            out.write_all(&[0u8; 8][..pad]).map_err(io)?;
        }
        out.flush().map_err(io)?;
        Ok(self.frames())
    }
}

/// The record of one frame: the time since `start` (whole microseconds, as candump logs
/// hold them), then the members of [`super::layout`].
fn record(r: &LogRecord, start: Duration, bus: u8, kind: FrameKind) -> [u8; 32] {
    let mut rec = [0u8; 32];
    let rel_us = r.timestamp.as_micros() as i128 - start.as_micros() as i128;
    rec[..TIME_BYTES].copy_from_slice(&(rel_us as f64 * 1e-6).to_le_bytes());
    rec[BUS_CHANNEL.byte_offset] = bus;
    let ext = r.frame.is_extended();
    let id = r.frame.raw_id() | if ext { ID_IDE_BIT } else { 0 };
    rec[ID.byte_offset..ID.byte_offset + 4].copy_from_slice(&id.to_le_bytes());
    rec[IDE.byte_offset] = u8::from(ext);
    rec[DLC.byte_offset] = r.frame.dlc() as u8;
    let dir = match kind {
        FrameKind::Data => {
            let data = r.frame.bytes();
            rec[DATA_LENGTH.byte_offset] = data.len() as u8;
            let at = DATA_BYTES.byte_offset;
            rec[at..at + data.len()].copy_from_slice(data);
            DATA_DIR
        }
        FrameKind::Remote => REMOTE_DIR,
    };
    if let Some(d) = r.direction {
        rec[dir.byte_offset] = u8::from(d == Direction::Tx);
    }
    rec
}

fn io(e: std::io::Error) -> Mf4Error {
    Mf4Error::Io(e.into())
}

/// The identification block: MDF 4.10, finalized.
fn id_block() -> [u8; ID_BLOCK_LEN as usize] {
    let mut id = [0u8; ID_BLOCK_LEN as usize];
    id[..8].copy_from_slice(MAGIC);
    id[8..16].copy_from_slice(b"4.10    ");
    id[16..24].copy_from_slice(b"ddct    ");
    id[28..30].copy_from_slice(&410u16.to_le_bytes());
    id
}

/// HD data: start time (ns since the epoch, UTC), no time zone, angle or distance.
fn hd_data(start_ns: u64) -> [u8; 32] {
    let mut d = [0u8; 32];
    d[..8].copy_from_slice(&start_ns.to_le_bytes());
    d
}

/// FH data: the time of the change (the start time, so that a conversion is reproducible).
fn fh_data(start_ns: u64) -> [u8; 16] {
    let mut d = [0u8; 16];
    d[..8].copy_from_slice(&start_ns.to_le_bytes());
    d
}

/// The DG, CG, SI and CN blocks of one group (its DG's data link is set later); the DG's offset.
fn group_blocks(b: &mut Builder, g: &Group) -> u64 {
    let name = b.text(&g.iface);
    let si = b.add(b"SI", &[name, name, 0], &[SI_BUS, SI_CAN, 0, 0, 0, 0, 0, 0]);
    let unit = b.text("s");
    let t_name = b.text("t");
    let master = b.add(
        b"CN",
        &[0, 0, t_name, 0, 0, 0, unit, 0],
        &cn_data(CN_MASTER, SYNC_TIME, DT_FLOAT_LE, 0, 64, 0),
    );
    let members: Vec<&Member> = g
        .kind
        .members()
        .iter()
        .filter(|m| m.name != "Dir" || g.directions)
        .collect();
    let mut member_cns = Vec::new();
    for m in &members {
        let n = b.text(&format!("{}.{}", g.kind.channel(), m.name));
        member_cns.push(b.add(
            b"CN",
            &[0, 0, n, 0, 0, 0, 0, 0],
            &cn_data(CN_FIXED, 0, m.data_type, m.byte_offset as u32, m.bits, 0),
        ));
    }
    for (prev, next) in member_cns.iter().zip(member_cns.iter().skip(1)) {
        b.set_link(*prev, 0, *next);
    }
    let frame_name = b.text(g.kind.channel());
    let bits = ((g.kind.record_len() - TIME_BYTES) * 8) as u32;
    let frame = b.add(
        b"CN",
        &[
            0,
            member_cns.first().copied().unwrap_or(0),
            frame_name,
            0,
            0,
            0,
            0,
            0,
        ],
        &cn_data(CN_FIXED, 0, DT_BYTES, TIME_BYTES as u32, bits, CN_BUS_EVENT),
    );
    b.set_link(master, 0, frame);
    let mut cg_data = [0u8; 32];
    cg_data[8..16].copy_from_slice(&g.count.to_le_bytes());
    cg_data[16..18].copy_from_slice(&CG_BUS_EVENT.to_le_bytes());
    cg_data[18..20].copy_from_slice(&u16::from(b'.').to_le_bytes());
    cg_data[24..28].copy_from_slice(&(g.kind.record_len() as u32).to_le_bytes());
    let cg = b.add(b"CG", &[0, master, name, si, 0, 0], &cg_data);
    b.add(b"DG", &[0, cg, 0, 0], &[0u8; 8])
}

/// The data section of a CN block.
fn cn_data(kind: u8, sync: u8, data_type: u8, byte_offset: u32, bits: u32, flags: u32) -> [u8; 72] {
    let mut d = [0u8; 72];
    d[0] = kind;
    d[1] = sync;
    d[2] = data_type;
    d[4..8].copy_from_slice(&byte_offset.to_le_bytes());
    d[8..12].copy_from_slice(&bits.to_le_bytes());
    d[12..16].copy_from_slice(&flags.to_le_bytes());
    d
}
