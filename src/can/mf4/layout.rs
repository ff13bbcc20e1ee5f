//! The record layout [`super::Mf4Writer`] writes (one channel group per interface and frame
//! kind, no record id): the time master as f64 seconds since the header's start time, then the
//! composed frame channel's members, byte-aligned so that any MDF reader maps them to plain
//! integer columns.

/// Which frames a channel group holds.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
pub(crate) enum FrameKind {
    Data,
    Remote,
}

impl FrameKind {
    /// The composed channel's name (ASAM bus logging).
    pub fn channel(self) -> &'static str {
        match self {
            FrameKind::Data => "CAN_DataFrame",
            FrameKind::Remote => "CAN_RemoteFrame",
        }
    }

    /// The members of the composed channel in this layout.
    pub fn members(self) -> &'static [Member] {
        match self {
            FrameKind::Data => DATA_MEMBERS,
            FrameKind::Remote => REMOTE_MEMBERS,
        }
    }

    /// Bytes per record: the time and the members.
    pub fn record_len(self) -> usize {
        self.members()
            .iter()
            .map(|m| m.byte_offset + m.bytes)
            .max()
            .unwrap_or(TIME_BYTES)
    }
}

/// MDF channel data types used here (cn_data_type).
pub(crate) const DT_UINT_LE: u8 = 0;
pub(crate) const DT_FLOAT_LE: u8 = 4;
pub(crate) const DT_BYTES: u8 = 10;

/// The time master: f64 little endian at offset 0.
pub(crate) const TIME_BYTES: usize = 8;

/// One member of the composed frame channel.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct Member {
    /// The part after `CAN_DataFrame.`.
    pub name: &'static str,
    pub byte_offset: usize,
    /// Bytes the member occupies.
    pub bytes: usize,
    /// Bits of the value (≤ 8 × bytes).
    pub bits: u32,
    pub data_type: u8,
}

const fn member(name: &'static str, byte_offset: usize, bytes: usize, bits: u32) -> Member {
    Member {
        name,
        byte_offset,
        bytes,
        bits,
        data_type: DT_UINT_LE,
    }
}

/// The members every frame kind has, at the same offsets.
pub(crate) const BUS_CHANNEL: Member = member("BusChannel", 8, 1, 8);
/// 29 bits of identifier; bit 31 repeats the IDE flag (CANedge's convention, which asammdf
/// falls back on when `IDE` is absent).
pub(crate) const ID: Member = member("ID", 9, 4, 32);
pub(crate) const IDE: Member = member("IDE", 13, 1, 1);
pub(crate) const DLC: Member = member("DLC", 14, 1, 4);
pub(crate) const DATA_LENGTH: Member = member("DataLength", 15, 1, 8);
pub(crate) const DATA_BYTES: Member = Member {
    name: "DataBytes",
    byte_offset: 16,
    bytes: 8,
    bits: 64,
    data_type: DT_BYTES,
};
pub(crate) const DATA_DIR: Member = member("Dir", 24, 1, 1);
pub(crate) const REMOTE_DIR: Member = member("Dir", 16, 1, 1);

const DATA_MEMBERS: &[Member] = &[BUS_CHANNEL, ID, IDE, DLC, DATA_LENGTH, DATA_BYTES, DATA_DIR];
const REMOTE_MEMBERS: &[Member] = &[BUS_CHANNEL, ID, IDE, DLC, DATA_LENGTH, REMOTE_DIR];

/// Bit 31 of the `ID` member: the frame has an extended identifier.
pub(crate) const ID_IDE_BIT: u32 = 1 << 31;
/// The identifier bits of the `ID` member.
pub(crate) const ID_MASK: u32 = 0x1FFF_FFFF;
