//! Reading the CAN frames of an MDF 4 file: every channel group holding a `CAN_DataFrame` or
//! `CAN_RemoteFrame` composition, its records cut out of the data group (sorted or unsorted,
//! data in `DT`, `DL`, `HL` or `DZ` blocks) and its members located by name, then the groups'
//! frames merged in time order.

use super::block::{self, Block};
use super::error::Mf4Error;
use super::layout::{FrameKind, ID_IDE_BIT, ID_MASK};
use crate::can::candump::{Direction, LogRecord};
use crate::can::frame::CanFrame;
use embedded_can::{ExtendedId, Id, StandardId};
use std::time::Duration;

/// Channel types (cn_type): master and virtual master; sync type time.
const CN_MASTER: u8 = 2;
const CN_VIRTUAL_MASTER: u8 = 3;
const SYNC_TIME: u8 = 1;
/// Channel group flag: VLSD records (cg_flags bit 0).
const CG_VLSD: u16 = 1;
/// Longest interface name Linux takes (IFNAMSIZ - 1).
const IFNAME_MAX: usize = 15;

/// Where a channel's value sits in a record and how it is coded.
#[derive(Debug, Clone, Copy)]
struct Field {
    byte_offset: usize,
    bit_offset: u32,
    bits: u32,
    data_type: u8,
    /// Linear conversion `offset + factor × raw` (identity: 0, 1).
    offset: f64,
    factor: f64,
}

impl Field {
    /// Bytes from `byte_offset` the value needs.
    fn span(&self) -> usize {
        (self.bit_offset + self.bits).div_ceil(8) as usize
    }

    /// The value as an unsigned integer (integers up to 64 bits).
    fn uint(&self, rec: &[u8]) -> u64 {
        let raw = &rec[self.byte_offset..self.byte_offset + self.span().min(8)];
        let mut b = [0u8; 8];
        let v = if matches!(self.data_type, 1 | 3 | 5) {
            b[8 - raw.len()..].copy_from_slice(raw);
            u64::from_be_bytes(b)
        } else {
            b[..raw.len()].copy_from_slice(raw);
            u64::from_le_bytes(b)
        };
        let v = v >> self.bit_offset;
        if self.bits >= 64 {
            v
        } else {
            v & ((1u64 << self.bits) - 1)
        }
    }

    /// The physical value: floats as they are, integers through the conversion.
    fn value(&self, rec: &[u8]) -> f64 {
        let raw = self.uint(rec);
        let v = match (self.data_type, self.bits) {
            (4 | 5, 64) => f64::from_bits(raw),
            (4 | 5, 32) => f64::from(f32::from_bits(raw as u32)),
            (2 | 3, n) if n < 64 && raw >> (n - 1) & 1 == 1 => (raw as i64 - (1i64 << n)) as f64,
            (2 | 3, _) => raw as i64 as f64,
            _ => raw as f64,
        };
        self.offset + self.factor * v
    }

    /// The value's bytes (byte arrays).
    fn bytes<'a>(&self, rec: &'a [u8]) -> &'a [u8] {
        &rec[self.byte_offset..self.byte_offset + (self.bits / 8) as usize]
    }
}

/// A channel as read from its CN block.
#[derive(Debug)]
struct Channel {
    name: String,
    kind: u8,
    sync: u8,
    field: Field,
    /// Members of a composed channel.
    members: Vec<Channel>,
}

/// A channel group that holds frames: where each member is.
#[derive(Debug)]
struct FrameGroup {
    kind: FrameKind,
    time: Field,
    bus: Option<Field>,
    id: Field,
    ide: Option<Field>,
    dlc: Option<Field>,
    data_length: Option<Field>,
    data: Option<Field>,
    dir: Option<Field>,
    /// The acquisition source's or the group's name.
    source_name: String,
    /// Record length without the record id.
    record_len: usize,
    records: Vec<u8>,
    /// Interface name per bus channel, decided once the records are in.
    iface: Vec<(u64, String)>,
    next: usize,
}

/// The frames of an MDF file in time order (each group's own order is kept; the groups are
/// merged by time, the earlier group first on a tie).
#[derive(Debug)]
pub struct Mf4Frames {
    groups: Vec<FrameGroup>,
    start_us: u64,
    /// Frames given so far (the index in errors).
    given: usize,
    /// Channel groups of the file that hold no CAN frames (other buses, error frames, signals).
    pub other_groups: usize,
}

/// Reads the CAN frames of an MDF 4 file held in memory.
pub fn read(file: &[u8]) -> Result<Mf4Frames, Mf4Error> {
    if !block::is_mdf(file) {
        return Err(Mf4Error::NotMdf);
    }
    let id = block::Block {
        kind: *b"ID",
        links: Vec::new(),
        data: file
            .get(..block::ID_BLOCK_LEN as usize)
            .ok_or(Mf4Error::Truncated {
                kind: "ID".into(),
                at: 0,
            })?,
    };
    let version = id.u16(28)?;
    if !(400..500).contains(&version) {
        return Err(Mf4Error::Version(version));
    }
    let (unfin, custom) = (id.u16(60)?, id.u16(62)?);
    if unfin != 0 || custom != 0 {
        return Err(Mf4Error::Unfinalized(unfin, custom));
    }
    let hd = block::expect(file, block::ID_BLOCK_LEN, b"HD")?;
    let start_us = hd.u64(0)? / 1000;
    let mut groups = Vec::new();
    let mut other_groups = 0;
    let mut dg_at = hd.link(0);
    let mut seen = 0usize;
    while dg_at != 0 {
        seen += 1;
        if seen > file.len() / block::HEADER_LEN {
            return Err(Mf4Error::Unsupported("the data group list loops".into()));
        }
        let dg = block::expect(file, dg_at, b"DG")?;
        let (found, others) = data_group(file, dg_at, &dg, groups.len())?;
        groups.extend(found);
        other_groups += others;
        dg_at = dg.link(0);
    }
    for g in &mut groups {
        name_interfaces(g);
    }
    Ok(Mf4Frames {
        groups,
        start_us,
        given: 0,
        other_groups,
    })
}

/// The frame groups of one data group with their records, and how many other groups it has.
fn data_group(
    file: &[u8],
    dg_at: u64,
    dg: &Block<'_>,
    numbered_from: usize,
) -> Result<(Vec<FrameGroup>, usize), Mf4Error> {
    let rec_id_size = usize::from(dg.u8(0)?);
    if !matches!(rec_id_size, 0 | 1 | 2 | 4 | 8) {
        return Err(Mf4Error::Unsupported(format!(
            "record id of {rec_id_size} bytes"
        )));
    }
    // Every channel group: its record id, record length (0 for VLSD) and frame layout.
    let mut cgs: Vec<(u64, usize, Option<FrameGroup>)> = Vec::new();
    let mut cg_at = dg.link(1);
    while cg_at != 0 {
        let cg = block::expect(file, cg_at, b"CG")?;
        let flags = cg.u16(16)?;
        let len = if flags & CG_VLSD != 0 {
            0
        } else {
            cg.u32(24)? as usize + cg.u32(28)? as usize
        };
        let group = frame_group(file, &cg, numbered_from + cgs.len())?;
        cgs.push((cg.u64(0)?, len, group));
        cg_at = cg.link(0);
        if cgs.len() > file.len() / block::HEADER_LEN {
            return Err(Mf4Error::Unsupported("the channel group list loops".into()));
        }
    }
    let others = cgs.iter().filter(|c| c.2.is_none()).count();
    if cgs.iter().all(|c| c.2.is_none()) {
        return Ok((Vec::new(), others));
    }
    let data = load_data(file, dg.link(2))?;
    split_records(&data, dg_at, rec_id_size, &mut cgs)?;
    Ok((cgs.into_iter().filter_map(|c| c.2).collect(), others))
}

/// Copies each record of `data` to its frame group (records of other groups are skipped).
fn split_records(
    data: &[u8],
    dg_at: u64,
    rec_id_size: usize,
    cgs: &mut [(u64, usize, Option<FrameGroup>)],
) -> Result<(), Mf4Error> {
    if rec_id_size == 0 {
        if cgs.len() != 1 {
            return Err(Mf4Error::Unsupported(
                "a data group with several channel groups and no record id".into(),
            ));
        }
        let (_, len, g) = &mut cgs[0];
        if let Some(g) = g {
            if *len == 0 || data.len() % *len != 0 {
                return Err(Mf4Error::PartialRecord { at: dg_at });
            }
            g.records = data.to_vec();
        }
        return Ok(());
    }
    let mut at = 0;
    while at < data.len() {
        let id_bytes = data
            .get(at..at + rec_id_size)
            .ok_or(Mf4Error::PartialRecord { at: dg_at })?;
        let mut b = [0u8; 8];
        b[..rec_id_size].copy_from_slice(id_bytes);
        let id = u64::from_le_bytes(b);
        at += rec_id_size;
        let (_, len, g) = cgs
            .iter_mut()
            .find(|c| c.0 == id)
            .ok_or(Mf4Error::RecordId { at: dg_at, id })?;
        let len = if *len == 0 {
            // VLSD: a 4-byte length, then the bytes.
            let n = data
                .get(at..at + 4)
                .ok_or(Mf4Error::PartialRecord { at: dg_at })?;
            at += 4;
            u32::from_le_bytes(n.try_into().unwrap_or([0; 4])) as usize
        } else {
            *len
        };
        let rec = data
            .get(at..at + len)
            .ok_or(Mf4Error::PartialRecord { at: dg_at })?;
        if let Some(g) = g {
            g.records.extend_from_slice(rec);
        }
        at += len;
    }
    Ok(())
}

/// The data of a data group: a `DT` block, a `DZ` block, a `DL` list of them or an `HL`
/// header of a list, concatenated.
fn load_data(file: &[u8], at: u64) -> Result<Vec<u8>, Mf4Error> {
    let mut out = Vec::new();
    append_data(file, at, &mut out, 0)?;
    Ok(out)
}

fn append_data(file: &[u8], at: u64, out: &mut Vec<u8>, depth: usize) -> Result<(), Mf4Error> {
    if at == 0 {
        return Ok(());
    }
    if depth > 4 {
        return Err(Mf4Error::Unsupported("data lists nested too deep".into()));
    }
    let b = block::read(file, at)?;
    match &b.kind {
        b"DT" => out.extend_from_slice(b.data),
        b"DZ" => out.extend_from_slice(&inflate(&b, at)?),
        b"HL" => append_data(file, b.link(0), out, depth + 1)?,
        b"DL" => {
            let mut dl_at = at;
            let mut lists = 0;
            while dl_at != 0 {
                let dl = block::expect(file, dl_at, b"DL")?;
                for link in dl.links.iter().skip(1) {
                    append_data(file, *link, out, depth + 1)?;
                }
                dl_at = dl.link(0);
                lists += 1;
                if lists > file.len() / block::HEADER_LEN {
                    return Err(Mf4Error::Unsupported("the data list loops".into()));
                }
            }
        }
        other => {
            return Err(Mf4Error::Unsupported(format!(
                "##{} data blocks",
                block::kind_text(*other)
            )))
        }
    }
    Ok(())
}

/// The original data of a `DZ` block: zlib deflate, optionally of the data transposed by
/// records (zip type 1, the record length as parameter).
fn inflate(b: &Block<'_>, at: u64) -> Result<Vec<u8>, Mf4Error> {
    let zip_type = b.u8(2)?;
    let columns = b.u32(4)? as usize;
    let org_len = b.u64(8)? as usize;
    let len = b.u64(16)? as usize;
    let packed = b.bytes(24, len)?;
    let data = miniz_oxide::inflate::decompress_to_vec_zlib_with_limit(packed, org_len)
        .map_err(|_| Mf4Error::Inflate { at })?;
    match zip_type {
        0 => Ok(data),
        1 if columns > 0 => {
            let rows = data.len() / columns;
            let mut out = data.clone();
            for r in 0..rows {
                for c in 0..columns {
                    out[r * columns + c] = data[c * rows + r];
                }
            }
            Ok(out)
        }
        z => Err(Mf4Error::Unsupported(format!("DZ zip type {z}"))),
    }
}

/// The frame layout of a channel group, `None` if it holds no CAN frames.
fn frame_group(file: &[u8], cg: &Block<'_>, index: usize) -> Result<Option<FrameGroup>, Mf4Error> {
    let channels = channel_list(file, cg.link(1), 0)?;
    let Some((kind, frame)) = channels.iter().find_map(|c| {
        [FrameKind::Data, FrameKind::Remote]
            .into_iter()
            .find(|k| c.name == k.channel())
            .map(|k| (k, c))
    }) else {
        return Ok(None);
    };
    let source_name = source_name(file, cg)?;
    let err = |what: String| Mf4Error::Channel {
        group: index,
        name: kind.channel().into(),
        what,
    };
    let time = time_master(&channels).map_err(err)?;
    let member = |name: &str| {
        frame
            .members
            .iter()
            .find(|m| {
                m.name == name
                    || m.name
                        .strip_prefix(kind.channel())
                        .and_then(|r| r.strip_prefix('.'))
                        == Some(name)
            })
            .map(|m| m.field)
    };
    let record_len = cg.u32(24)? as usize;
    let id = member("ID").ok_or_else(|| err("no ID member".into()))?;
    let data = member("DataBytes");
    if kind == FrameKind::Data && data.is_none() {
        return Err(err("no DataBytes member".into()));
    }
    let g = FrameGroup {
        kind,
        time,
        bus: member("BusChannel"),
        id,
        ide: member("IDE"),
        dlc: member("DLC"),
        data_length: member("DataLength"),
        data,
        dir: member("Dir"),
        source_name,
        record_len,
        records: Vec::new(),
        iface: Vec::new(),
        next: 0,
    };
    g.check_bounds().map_err(err)?;
    Ok(Some(g))
}

/// The time master channel's field: a recorded (not virtual) time with a linear conversion.
fn time_master(channels: &[Channel]) -> Result<Field, String> {
    let time = channels
        .iter()
        .find(|c| matches!(c.kind, CN_MASTER | CN_VIRTUAL_MASTER) && c.sync == SYNC_TIME)
        .ok_or("no time master channel")?;
    if time.kind == CN_VIRTUAL_MASTER {
        return Err("a virtual time master (no time in the records)".into());
    }
    if !time.field.factor.is_finite() {
        return Err("the time channel has a conversion other than linear".into());
    }
    Ok(time.field)
}

impl FrameGroup {
    /// Every member inside the record, at least one bit and integers at most 64 bits wide.
    fn check_bounds(&self) -> Result<(), String> {
        let members = [
            ("time", Some(self.time)),
            ("ID", Some(self.id)),
            ("DataBytes", self.data),
            ("BusChannel", self.bus),
            ("IDE", self.ide),
            ("DLC", self.dlc),
            ("DataLength", self.data_length),
            ("Dir", self.dir),
        ];
        for (name, f) in members {
            let Some(f) = f else { continue };
            let width = f.bits == 0 || (f.data_type != 10 && f.bits > 64);
            if width || f.byte_offset + f.span() > self.record_len {
                return Err(format!(
                    "member {name} (byte {}, {} bits) is empty, too wide or outside the {}-byte record",
                    f.byte_offset, f.bits, self.record_len
                ));
            }
        }
        Ok(())
    }
}

/// The acquisition source's name of a channel group, else the group's acquisition name.
fn source_name(file: &[u8], cg: &Block<'_>) -> Result<String, Mf4Error> {
    if cg.link(3) != 0 {
        let si = block::expect(file, cg.link(3), b"SI")?;
        let name = block::text(file, si.link(0))?;
        if !name.is_empty() {
            return Ok(name);
        }
    }
    block::text(file, cg.link(2))
}

/// The channels of a CN list from `at`, each with its composition's members.
fn channel_list(file: &[u8], mut at: u64, depth: usize) -> Result<Vec<Channel>, Mf4Error> {
    let mut out = Vec::new();
    while at != 0 {
        let cn = block::expect(file, at, b"CN")?;
        let conv = conversion(file, cn.link(4))?;
        let composition = cn.link(1);
        let members = if composition != 0 && depth < 4 {
            match block::read(file, composition)?.kind {
                [b'C', b'N'] => channel_list(file, composition, depth + 1)?,
                _ => Vec::new(), // an array (CA) block: not a frame member
            }
        } else {
            Vec::new()
        };
        out.push(Channel {
            name: block::text(file, cn.link(2))?,
            kind: cn.u8(0)?,
            sync: cn.u8(1)?,
            field: Field {
                byte_offset: cn.u32(4)? as usize,
                bit_offset: u32::from(cn.u8(3)?),
                bits: cn.u32(8)?,
                data_type: cn.u8(2)?,
                offset: conv.0,
                factor: conv.1,
            },
            members,
        });
        at = cn.link(0);
        if out.len() > file.len() / block::HEADER_LEN {
            return Err(Mf4Error::Unsupported("the channel list loops".into()));
        }
    }
    Ok(out)
}

/// A channel's conversion as (offset, factor): identity for none, linear as given, NaN for
/// any other.
fn conversion(file: &[u8], at: u64) -> Result<(f64, f64), Mf4Error> {
    if at == 0 {
        return Ok((0.0, 1.0));
    }
    let cc = block::expect(file, at, b"CC")?;
    match cc.u8(0)? {
        0 => Ok((0.0, 1.0)),
        1 => Ok((cc.f64(24)?, cc.f64(32)?)),
        // Value-to-text and other conversions: the members are read raw; the time channel
        // refuses a conversion it cannot apply (see `frame_group`).
        _ => Ok((f64::NAN, f64::NAN)),
    }
}

/// Names each bus channel of a group: the source's name when it is a valid interface name and
/// the group holds one bus channel, else `can<N>` for bus channel N.
fn name_interfaces(g: &mut FrameGroup) {
    let mut buses: Vec<u64> = Vec::new();
    if g.record_len > 0 {
        for rec in g.records.chunks_exact(g.record_len) {
            let b = g.bus.map_or(0, |f| f.uint(rec));
            if !buses.contains(&b) {
                buses.push(b);
            }
        }
    }
    let valid = !g.source_name.is_empty()
        && g.source_name.len() <= IFNAME_MAX
        && g.source_name
            .bytes()
            .all(|c| c.is_ascii_alphanumeric() || b"_-.".contains(&c));
    g.iface = buses
        .iter()
        .map(|b| {
            let name = if valid && buses.len() == 1 {
                g.source_name.clone()
            } else {
                format!("can{b}")
            };
            (*b, name)
        })
        .collect();
}

impl FrameGroup {
    fn len(&self) -> usize {
        self.records.len().checked_div(self.record_len).unwrap_or(0)
    }

    fn record(&self, i: usize) -> &[u8] {
        &self.records[i * self.record_len..(i + 1) * self.record_len]
    }

    /// The time of record `i` since the file's start (µs).
    fn time_us(&self, i: usize) -> f64 {
        (self.time.value(self.record(i)) * 1e6).round()
    }

    fn frame(&self, i: usize) -> Result<(CanFrame, String, Option<Direction>), String> {
        let rec = self.record(i);
        let raw_id = self.id.uint(rec) as u32;
        let ext = match self.ide {
            Some(f) => f.uint(rec) != 0,
            None => raw_id & ID_IDE_BIT != 0,
        };
        let id_value = raw_id & ID_MASK;
        let id = if ext {
            ExtendedId::new(id_value).map(Id::Extended)
        } else {
            u16::try_from(id_value)
                .ok()
                .and_then(StandardId::new)
                .map(Id::Standard)
        }
        .ok_or_else(|| format!("id 0x{id_value:X} is not a valid CAN id"))?;
        let dlc = self.dlc.map(|f| f.uint(rec) as usize);
        let len = self
            .data_length
            .map(|f| f.uint(rec) as usize)
            .or(dlc)
            .unwrap_or(0);
        let frame = match self.kind {
            FrameKind::Remote => CanFrame::remote(id, dlc.unwrap_or(len)),
            FrameKind::Data => {
                let bytes = self.data.map_or(&[][..], |f| f.bytes(rec));
                if len > 8 {
                    return Err(format!(
                        "{len} data bytes: only classic CAN frames are read"
                    ));
                }
                let data = bytes
                    .get(..len)
                    .ok_or_else(|| format!("data length {len} but {} data bytes", bytes.len()))?;
                CanFrame::with_id(id, data)
            }
        }
        .map_err(|e| e.to_string())?;
        let bus = self.bus.map_or(0, |f| f.uint(rec));
        let iface = self
            .iface
            .iter()
            .find(|(b, _)| *b == bus)
            .map_or_else(|| format!("can{bus}"), |(_, n)| n.clone());
        let dir = self.dir.map(|f| {
            if f.uint(rec) != 0 {
                Direction::Tx
            } else {
                Direction::Rx
            }
        });
        Ok((frame, iface, dir))
    }
}

impl Mf4Frames {
    /// Frames in the file.
    pub fn len(&self) -> usize {
        self.groups.iter().map(FrameGroup::len).sum()
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
}

impl Iterator for Mf4Frames {
    type Item = Result<LogRecord, Mf4Error>;

    fn next(&mut self) -> Option<Self::Item> {
        let (gi, t_us) = self
            .groups
            .iter()
            .enumerate()
            .filter(|(_, g)| g.next < g.len())
            .map(|(i, g)| (i, g.time_us(g.next)))
            .min_by(|a, b| a.1.total_cmp(&b.1))?;
        let index = self.given;
        self.given += 1;
        let g = &mut self.groups[gi];
        let i = g.next;
        g.next += 1;
        let at_us = self.start_us as f64 + t_us;
        if !at_us.is_finite() || at_us < 0.0 {
            return Some(Err(Mf4Error::Frame {
                index,
                what: format!("time {t_us} µs from the start is not a time"),
            }));
        }
        Some(
            g.frame(i)
                .map(|(frame, iface, direction)| LogRecord {
                    timestamp: Duration::from_micros(at_us as u64),
                    iface,
                    frame,
                    direction,
                })
                .map_err(|what| Mf4Error::Frame { index, what }),
        )
    }
}
