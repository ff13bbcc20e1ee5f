//! The XCP packet codec (ASAM MCD-1 XCP 1.x, protocol layer): the command codes, the error
//! codes, the decoding of one command packet (CRO) into a typed [`Request`] and the encoding of
//! the response (`FF …`) and error (`FE code`) packets.
//!
//! On CAN an XCP packet is the data field of one frame: no header, no tail (XCP on CAN 1.x). A
//! master may pad a CRO to 8 bytes (pyxcp's `MAX_DLC_REQUIRED`), so bytes after a command's
//! layout are ignored; a CRO shorter than its layout is `ERR_CMD_SYNTAX`. Words and double words
//! are Intel (little-endian), the byte order the slave declares in CONNECT.
//!
//! | code | command | layout (byte: field) |
//! |---|---|---|
//! | FF | CONNECT | 1: mode |
//! | FE | DISCONNECT | |
//! | FD | GET_STATUS | |
//! | FC | SYNCH | |
//! | FB | GET_COMM_MODE_INFO | |
//! | FA | GET_ID | 1: type |
//! | F6 | SET_MTA | 3: address extension, 4–7: address |
//! | F5 | UPLOAD | 1: n |
//! | F4 | SHORT_UPLOAD | 1: n, 3: address extension, 4–7: address |
//! | F0 | DOWNLOAD | 1: n, 2…: n data bytes |
//! | E3 | CLEAR_DAQ_LIST | 2–3: DAQ list |
//! | E2 | SET_DAQ_PTR | 2–3: DAQ list, 4: ODT, 5: ODT entry |
//! | E1 | WRITE_DAQ | 1: bit offset (FF: none), 2: size, 3: address extension, 4–7: address |
//! | E0 | SET_DAQ_LIST_MODE | 1: mode, 2–3: DAQ list, 4–5: event channel, 6: prescaler, 7: priority |
//! | DF | GET_DAQ_LIST_MODE | 2–3: DAQ list |
//! | DE | START_STOP_DAQ_LIST | 1: mode (0 stop, 1 start, 2 select), 2–3: DAQ list |
//! | DD | START_STOP_SYNCH | 1: mode (0 stop all, 1 start selected, 2 stop selected) |
//! | DC | GET_DAQ_CLOCK | |
//! | DB | READ_DAQ | |
//! | DA | GET_DAQ_PROCESSOR_INFO | |
//! | D9 | GET_DAQ_RESOLUTION_INFO | |
//! | D8 | GET_DAQ_LIST_INFO | 2–3: DAQ list |
//! | D7 | GET_DAQ_EVENT_INFO | 2–3: event channel |
//! | D6 | FREE_DAQ | |
//! | D5 | ALLOC_DAQ | 2–3: count |
//! | D4 | ALLOC_ODT | 2–3: DAQ list, 4: count |
//! | D3 | ALLOC_ODT_ENTRY | 2–3: DAQ list, 4: ODT, 5: count |
//!
//! Any other code (the other optional commands of the standard included) is `ERR_CMD_UNKNOWN`.

/// Packet identifier of a positive response.
pub(crate) const PID_RES: u8 = 0xFF;
/// Packet identifier of an error packet.
pub(crate) const PID_ERR: u8 = 0xFE;

/// The commands this slave implements, by their code (the packet identifier of a CRO).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(u8)]
pub enum Command {
    Connect = 0xFF,
    Disconnect = 0xFE,
    GetStatus = 0xFD,
    Synch = 0xFC,
    GetCommModeInfo = 0xFB,
    GetId = 0xFA,
    SetMta = 0xF6,
    Upload = 0xF5,
    ShortUpload = 0xF4,
    Download = 0xF0,
    ClearDaqList = 0xE3,
    SetDaqPtr = 0xE2,
    WriteDaq = 0xE1,
    SetDaqListMode = 0xE0,
    GetDaqListMode = 0xDF,
    StartStopDaqList = 0xDE,
    StartStopSynch = 0xDD,
    GetDaqClock = 0xDC,
    ReadDaq = 0xDB,
    GetDaqProcessorInfo = 0xDA,
    GetDaqResolutionInfo = 0xD9,
    GetDaqListInfo = 0xD8,
    GetDaqEventInfo = 0xD7,
    FreeDaq = 0xD6,
    AllocDaq = 0xD5,
    AllocOdt = 0xD4,
    AllocOdtEntry = 0xD3,
}

impl Command {
    /// Every implemented command.
    pub const ALL: [Command; 27] = [
        Command::Connect,
        Command::Disconnect,
        Command::GetStatus,
        Command::Synch,
        Command::GetCommModeInfo,
        Command::GetId,
        Command::SetMta,
        Command::Upload,
        Command::ShortUpload,
        Command::Download,
        Command::ClearDaqList,
        Command::SetDaqPtr,
        Command::WriteDaq,
        Command::SetDaqListMode,
        Command::GetDaqListMode,
        Command::StartStopDaqList,
        Command::StartStopSynch,
        Command::GetDaqClock,
        Command::ReadDaq,
        Command::GetDaqProcessorInfo,
        Command::GetDaqResolutionInfo,
        Command::GetDaqListInfo,
        Command::GetDaqEventInfo,
        Command::FreeDaq,
        Command::AllocDaq,
        Command::AllocOdt,
        Command::AllocOdtEntry,
    ];

    /// The command of a code, if implemented.
    pub fn from_code(code: u8) -> Option<Command> {
        Self::ALL.iter().copied().find(|c| *c as u8 == code)
    }

    /// Bytes of the command's layout (a shorter CRO is `ERR_CMD_SYNTAX`).
    fn min_len(self) -> usize {
        use Command::*;
        match self {
            Disconnect | GetStatus | Synch | GetCommModeInfo | GetDaqClock | ReadDaq
            | GetDaqProcessorInfo | GetDaqResolutionInfo | FreeDaq => 1,
            Connect | GetId | Upload | StartStopSynch | Download => 2,
            ClearDaqList | GetDaqListMode | StartStopDaqList | GetDaqListInfo | GetDaqEventInfo
            | AllocDaq => 4,
            AllocOdt => 5,
            SetDaqPtr | AllocOdtEntry => 6,
            SetMta | ShortUpload | WriteDaq | SetDaqListMode => 8,
        }
    }
}

/// The standard error codes (the second byte of an error packet `FE code`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(u8)]
pub enum ErrorCode {
    /// The answer to SYNCH.
    CmdSynch = 0x00,
    CmdBusy = 0x10,
    DaqActive = 0x11,
    PgmActive = 0x12,
    CmdUnknown = 0x20,
    CmdSyntax = 0x21,
    OutOfRange = 0x22,
    WriteProtected = 0x23,
    AccessDenied = 0x24,
    AccessLocked = 0x25,
    PageNotValid = 0x26,
    ModeNotValid = 0x27,
    SegmentNotValid = 0x28,
    Sequence = 0x29,
    DaqConfig = 0x2A,
    MemoryOverflow = 0x30,
    Generic = 0x31,
    Verify = 0x32,
}

/// One decoded command.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Request<'a> {
    Connect {
        mode: u8,
    },
    Disconnect,
    GetStatus,
    Synch,
    GetCommModeInfo,
    GetId {
        id_type: u8,
    },
    SetMta {
        ext: u8,
        address: u32,
    },
    Upload {
        n: u8,
    },
    ShortUpload {
        n: u8,
        ext: u8,
        address: u32,
    },
    /// `data`: everything after `F0 n` (n data bytes, then any padding).
    Download {
        n: u8,
        data: &'a [u8],
    },
    ClearDaqList {
        daq: u16,
    },
    SetDaqPtr {
        daq: u16,
        odt: u8,
        entry: u8,
    },
    WriteDaq {
        bit_offset: u8,
        size: u8,
        ext: u8,
        address: u32,
    },
    SetDaqListMode {
        mode: u8,
        daq: u16,
        event: u16,
        prescaler: u8,
        priority: u8,
    },
    GetDaqListMode {
        daq: u16,
    },
    StartStopDaqList {
        mode: u8,
        daq: u16,
    },
    StartStopSynch {
        mode: u8,
    },
    GetDaqClock,
    ReadDaq,
    GetDaqProcessorInfo,
    GetDaqResolutionInfo,
    GetDaqListInfo {
        daq: u16,
    },
    GetDaqEventInfo {
        event: u16,
    },
    FreeDaq,
    AllocDaq {
        count: u16,
    },
    AllocOdt {
        daq: u16,
        count: u8,
    },
    AllocOdtEntry {
        daq: u16,
        odt: u8,
        count: u8,
    },
}

fn word(b: &[u8], at: usize) -> u16 {
    u16::from_le_bytes([b[at], b[at + 1]])
}

fn dword(b: &[u8], at: usize) -> u32 {
    u32::from_le_bytes([b[at], b[at + 1], b[at + 2], b[at + 3]])
}

/// Decodes a CRO: `None` for an empty packet; `ERR_CMD_UNKNOWN` for a code not implemented,
/// `ERR_CMD_SYNTAX` for a packet shorter than its layout.
pub fn decode(cro: &[u8]) -> Option<Result<Request<'_>, ErrorCode>> {
    let code = *cro.first()?;
    let Some(cmd) = Command::from_code(code) else {
        return Some(Err(ErrorCode::CmdUnknown));
    };
    if cro.len() < cmd.min_len() {
        return Some(Err(ErrorCode::CmdSyntax));
    }
    // Every index below is inside `min_len`, checked above.
    Some(Ok(decode_checked(cmd, cro)))
}

fn decode_checked(cmd: Command, b: &[u8]) -> Request<'_> {
    use Command as C;
    match cmd {
        C::Connect => Request::Connect { mode: b[1] },
        C::Disconnect => Request::Disconnect,
        C::GetStatus => Request::GetStatus,
        C::Synch => Request::Synch,
        C::GetCommModeInfo => Request::GetCommModeInfo,
        C::GetId => Request::GetId { id_type: b[1] },
        C::SetMta => Request::SetMta {
            ext: b[3],
            address: dword(b, 4),
        },
        C::Upload => Request::Upload { n: b[1] },
        C::ShortUpload => Request::ShortUpload {
            n: b[1],
            ext: b[3],
            address: dword(b, 4),
        },
        // The data length is checked by the slave against the packet (ERR_CMD_SYNTAX).
        C::Download => Request::Download {
            n: b[1],
            data: &b[2..],
        },
        C::ClearDaqList => Request::ClearDaqList { daq: word(b, 2) },
        C::SetDaqPtr => Request::SetDaqPtr {
            daq: word(b, 2),
            odt: b[4],
            entry: b[5],
        },
        C::WriteDaq => Request::WriteDaq {
            bit_offset: b[1],
            size: b[2],
            ext: b[3],
            address: dword(b, 4),
        },
        C::SetDaqListMode => Request::SetDaqListMode {
            mode: b[1],
            daq: word(b, 2),
            event: word(b, 4),
            prescaler: b[6],
            priority: b[7],
        },
        C::GetDaqListMode => Request::GetDaqListMode { daq: word(b, 2) },
        C::StartStopDaqList => Request::StartStopDaqList {
            mode: b[1],
            daq: word(b, 2),
        },
        C::StartStopSynch => Request::StartStopSynch { mode: b[1] },
        C::GetDaqClock => Request::GetDaqClock,
        C::ReadDaq => Request::ReadDaq,
        C::GetDaqProcessorInfo => Request::GetDaqProcessorInfo,
        C::GetDaqResolutionInfo => Request::GetDaqResolutionInfo,
        C::GetDaqListInfo => Request::GetDaqListInfo { daq: word(b, 2) },
        C::GetDaqEventInfo => Request::GetDaqEventInfo { event: word(b, 2) },
        C::FreeDaq => Request::FreeDaq,
        C::AllocDaq => Request::AllocDaq { count: word(b, 2) },
        C::AllocOdt => Request::AllocOdt {
            daq: word(b, 2),
            count: b[4],
        },
        C::AllocOdtEntry => Request::AllocOdtEntry {
            daq: word(b, 2),
            odt: b[4],
            count: b[5],
        },
    }
}

/// A positive response: `FF` and the parameters.
pub fn positive(params: &[u8]) -> Vec<u8> {
    let mut p = Vec::with_capacity(1 + params.len());
    p.push(PID_RES);
    p.extend_from_slice(params);
    p
}

/// An error packet: `FE code`.
pub fn error(code: ErrorCode) -> Vec<u8> {
    vec![PID_ERR, code as u8]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn codes_round_trip_and_unknown_codes_are_refused() {
        for c in Command::ALL {
            assert_eq!(Command::from_code(c as u8), Some(c));
        }
        assert_eq!(decode(&[0xF8, 0, 0]), Some(Err(ErrorCode::CmdUnknown))); // GET_SEED
        assert_eq!(decode(&[0x00]), Some(Err(ErrorCode::CmdUnknown)));
        assert_eq!(decode(&[]), None);
    }

    #[test]
    fn layouts_decode_intel_words_and_ignore_padding() {
        let r = decode(&[0xE0, 0x10, 0x01, 0x00, 0x00, 0x00, 0x01, 0x00]);
        assert_eq!(
            r,
            Some(Ok(Request::SetDaqListMode {
                mode: 0x10,
                daq: 1,
                event: 0,
                prescaler: 1,
                priority: 0
            }))
        );
        let r = decode(&[0xF6, 0, 0, 0, 0x04, 0x00, 0x01, 0x00]);
        assert_eq!(
            r,
            Some(Ok(Request::SetMta {
                ext: 0,
                address: 0x0001_0004
            }))
        );
        // CONNECT padded to 8 bytes with 0x00 (pyxcp MAX_DLC_REQUIRED).
        assert_eq!(
            decode(&[0xFF, 0, 0, 0, 0, 0, 0, 0]),
            Some(Ok(Request::Connect { mode: 0 }))
        );
        assert_eq!(decode(&[0xE2, 0, 0, 0, 0]), Some(Err(ErrorCode::CmdSyntax)));
        assert_eq!(decode(&[0xF6, 0, 0, 0]), Some(Err(ErrorCode::CmdSyntax)));
    }
}
