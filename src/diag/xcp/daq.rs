//! Dynamic DAQ lists (ASAM MCD-1 XCP 1.x, "dynamic DAQ configuration"): the allocation
//! (FREE_DAQ, ALLOC_DAQ, ALLOC_ODT, ALLOC_ODT_ENTRY, in this order), the DAQ pointer
//! (SET_DAQ_PTR, WRITE_DAQ, READ_DAQ), the list modes (SET_DAQ_LIST_MODE, GET_DAQ_LIST_MODE),
//! starting and stopping (START_STOP_DAQ_LIST, START_STOP_SYNCH) and the sampling of the running
//! lists at an event ([`DaqTables::sample`]).
//!
//! Bounded resources: at most [`MAX_DAQ_LISTS`] lists, [`MAX_ODTS_PER_LIST`] ODTs per list and
//! [`MAX_ODTS`] in all, [`MAX_ENTRIES_PER_ODT`] entries per ODT and [`MAX_ENTRIES`] in all;
//! an allocation beyond them is `ERR_MEMORY_OVERFLOW` and changes nothing. Allocation out of
//! order (ALLOC_DAQ after ALLOC_ODT, ALLOC_ODT after ALLOC_ODT_ENTRY, …) is `ERR_SEQUENCE`.
//! Dynamic lists are numbered from MIN_DAQ = 0.
//!
//! A DAQ packet (DTO) is `PID [timestamp] data…`: the PID is the absolute ODT number (the ODTs
//! of list 0, then of list 1, …; START_STOP_DAQ_LIST answers a list's first PID), the
//! timestamp (4 bytes, Intel, 1 µs ticks of `now`, wrapping) is in the first ODT of a sample when
//! the list's mode has TIMESTAMP (0x10), and the data are the entries' bytes in entry order. An
//! ODT must fit one DTO (MAX_DTO = 8: 7 bytes after the PID, 3 in a timestamped first ODT);
//! starting or selecting a list that does not, or has no ODT, is `ERR_DAQ_CONFIG`. An ODT with
//! no entry is sent as its PID (and timestamp): pyxcp leaves the first ODT empty when a
//! timestamp leaves no room for its 4-byte values.

use std::time::Duration;

use super::ecu::XcpEcu;
use super::memory;
use super::packet::ErrorCode;
use crate::diag::values::Snapshot;

/// Most DAQ lists.
pub const MAX_DAQ_LISTS: u16 = 4;
/// Most ODTs in one list.
pub const MAX_ODTS_PER_LIST: u8 = 32;
/// Most ODTs in all lists (absolute ODT numbers stay below the response PIDs 0xFC–0xFF).
pub const MAX_ODTS: usize = 64;
/// Most entries in one ODT (one byte each fills a DTO).
pub const MAX_ENTRIES_PER_ODT: u8 = 7;
/// Most entries in all ODTs.
pub const MAX_ENTRIES: usize = 256;
/// Largest ODT entry (bytes): a whole DTO after the PID.
pub(crate) const MAX_ODT_ENTRY_SIZE: u8 = 7;
/// Bytes of a DTO (MAX_DTO).
pub(crate) const MAX_DTO: usize = 8;
/// Bytes of the DAQ timestamp.
pub(crate) const TIMESTAMP_SIZE: usize = 4;

/// SET_DAQ_LIST_MODE / GET_DAQ_LIST_MODE bits.
pub(crate) const MODE_SELECTED: u8 = 0x01;
pub const MODE_DIRECTION_STIM: u8 = 0x02;
pub(crate) const MODE_TIMESTAMP: u8 = 0x10;
pub const MODE_PID_OFF: u8 = 0x20;
pub(crate) const MODE_RUNNING: u8 = 0x40;

#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
struct Entry {
    /// 0: not written.
    size: u8,
    address: u32,
}

#[derive(Debug, Clone, Default, PartialEq)]
struct DaqList {
    odts: Vec<Vec<Entry>>,
    timestamp: bool,
    event: u16,
    prescaler: u8,
    priority: u8,
    selected: bool,
    running: bool,
    /// Events since the last sample (prescaler).
    count: u8,
}

/// Where the dynamic allocation stands.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Stage {
    Freed,
    Lists,
    Odts,
    Entries,
}

/// The DAQ pointer: list, ODT, entry.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
struct Ptr {
    daq: usize,
    odt: usize,
    entry: usize,
}

/// The lists of the dynamic DAQ configuration.
#[derive(Debug, Clone)]
pub(crate) struct DaqTables {
    lists: Vec<DaqList>,
    stage: Stage,
    ptr: Option<Ptr>,
}

impl Default for DaqTables {
    fn default() -> Self {
        DaqTables {
            lists: Vec::new(),
            stage: Stage::Freed,
            ptr: None,
        }
    }
}

impl DaqTables {
    fn list(&self, daq: u16) -> Result<&DaqList, ErrorCode> {
        self.lists
            .get(usize::from(daq))
            .ok_or(ErrorCode::OutOfRange)
    }

    fn list_mut(&mut self, daq: u16) -> Result<&mut DaqList, ErrorCode> {
        self.lists
            .get_mut(usize::from(daq))
            .ok_or(ErrorCode::OutOfRange)
    }

    fn odt_count(&self) -> usize {
        self.lists.iter().map(|l| l.odts.len()).sum()
    }

    fn entry_count(&self) -> usize {
        self.lists.iter().flat_map(|l| &l.odts).map(Vec::len).sum()
    }

    /// Whether any list is running.
    pub fn running(&self) -> bool {
        self.lists.iter().any(|l| l.running)
    }

    /// FREE_DAQ: every list gone (running ones stopped).
    pub fn free(&mut self) {
        *self = DaqTables::default();
    }

    /// ALLOC_DAQ.
    pub fn alloc_daq(&mut self, count: u16) -> Result<(), ErrorCode> {
        if self.stage != Stage::Freed {
            return Err(ErrorCode::Sequence);
        }
        if count > MAX_DAQ_LISTS {
            return Err(ErrorCode::MemoryOverflow);
        }
        self.lists = vec![
            DaqList {
                prescaler: 1,
                ..DaqList::default()
            };
            usize::from(count)
        ];
        self.stage = Stage::Lists;
        Ok(())
    }

    /// ALLOC_ODT: `count` more ODTs for list `daq`.
    pub fn alloc_odt(&mut self, daq: u16, count: u8) -> Result<(), ErrorCode> {
        if !matches!(self.stage, Stage::Lists | Stage::Odts) {
            return Err(ErrorCode::Sequence);
        }
        let total = self.odt_count() + usize::from(count);
        let list = self.list_mut(daq)?;
        if list.running {
            return Err(ErrorCode::DaqActive);
        }
        if list.odts.len() + usize::from(count) > usize::from(MAX_ODTS_PER_LIST) || total > MAX_ODTS
        {
            return Err(ErrorCode::MemoryOverflow);
        }
        list.odts
            .extend(std::iter::repeat_n(Vec::new(), usize::from(count)));
        self.stage = Stage::Odts;
        Ok(())
    }

    /// ALLOC_ODT_ENTRY: `count` entries for ODT `odt` of list `daq` (0 allowed: an ODT that
    /// carries only its PID and timestamp).
    pub fn alloc_odt_entry(&mut self, daq: u16, odt: u8, count: u8) -> Result<(), ErrorCode> {
        if !matches!(self.stage, Stage::Odts | Stage::Entries) {
            return Err(ErrorCode::Sequence);
        }
        let others = self.entry_count();
        let list = self.list_mut(daq)?;
        if list.running {
            return Err(ErrorCode::DaqActive);
        }
        let entries = list
            .odts
            .get_mut(usize::from(odt))
            .ok_or(ErrorCode::OutOfRange)?;
        let total = others - entries.len() + usize::from(count);
        if count > MAX_ENTRIES_PER_ODT || total > MAX_ENTRIES {
            return Err(ErrorCode::MemoryOverflow);
        }
        *entries = vec![Entry::default(); usize::from(count)];
        self.stage = Stage::Entries;
        Ok(())
    }

    /// SET_DAQ_PTR.
    pub fn set_ptr(&mut self, daq: u16, odt: u8, entry: u8) -> Result<(), ErrorCode> {
        let list = self.list(daq)?;
        if list.running {
            return Err(ErrorCode::DaqActive);
        }
        let entries = list
            .odts
            .get(usize::from(odt))
            .ok_or(ErrorCode::OutOfRange)?;
        if usize::from(entry) >= entries.len() {
            return Err(ErrorCode::OutOfRange);
        }
        self.ptr = Some(Ptr {
            daq: usize::from(daq),
            odt: usize::from(odt),
            entry: usize::from(entry),
        });
        Ok(())
    }

    fn entry_at_ptr(&mut self) -> Result<(&mut Entry, &mut Ptr), ErrorCode> {
        let ptr = self.ptr.as_mut().ok_or(ErrorCode::Sequence)?;
        let list = self.lists.get_mut(ptr.daq).ok_or(ErrorCode::Sequence)?;
        if list.running {
            return Err(ErrorCode::DaqActive);
        }
        let entry = list
            .odts
            .get_mut(ptr.odt)
            .and_then(|o| o.get_mut(ptr.entry))
            .ok_or(ErrorCode::OutOfRange)?;
        Ok((entry, ptr))
    }

    /// WRITE_DAQ: the entry at the pointer, then the pointer to the next entry.
    pub fn write(
        &mut self,
        bit_offset: u8,
        size: u8,
        ext: u8,
        address: u32,
        ecu: &impl XcpEcu,
    ) -> Result<(), ErrorCode> {
        if bit_offset != 0xFF || ext != 0 || size == 0 || size > MAX_ODT_ENTRY_SIZE {
            return Err(ErrorCode::OutOfRange);
        }
        if !memory::readable(address, size, ecu) {
            return Err(ErrorCode::AccessDenied);
        }
        let (entry, ptr) = self.entry_at_ptr()?;
        *entry = Entry { size, address };
        ptr.entry += 1;
        Ok(())
    }

    /// READ_DAQ: `bit offset, size, extension, address` of the entry at the pointer, then the
    /// pointer to the next entry.
    pub fn read(&mut self) -> Result<[u8; 7], ErrorCode> {
        let (entry, ptr) = self.entry_at_ptr()?;
        let a = entry.address.to_le_bytes();
        let out = [0xFF, entry.size, 0, a[0], a[1], a[2], a[3]];
        ptr.entry += 1;
        Ok(out)
    }

    /// CLEAR_DAQ_LIST: the list stopped, unselected, its entries unwritten.
    pub fn clear(&mut self, daq: u16) -> Result<(), ErrorCode> {
        let list = self.list_mut(daq)?;
        for e in list.odts.iter_mut().flatten() {
            *e = Entry::default();
        }
        list.running = false;
        list.selected = false;
        list.count = 0;
        Ok(())
    }

    /// SET_DAQ_LIST_MODE (only TIMESTAMP among the mode bits; only event channel 0).
    pub fn set_mode(
        &mut self,
        mode: u8,
        daq: u16,
        event: u16,
        prescaler: u8,
        priority: u8,
    ) -> Result<(), ErrorCode> {
        let list = self.list_mut(daq)?;
        if list.running {
            return Err(ErrorCode::DaqActive);
        }
        if mode & !MODE_TIMESTAMP != 0 || event != 0 {
            return Err(ErrorCode::OutOfRange);
        }
        list.timestamp = mode & MODE_TIMESTAMP != 0;
        list.event = event;
        list.prescaler = prescaler.max(1);
        list.priority = priority;
        Ok(())
    }

    /// GET_DAQ_LIST_MODE: `mode, reserved, reserved, event (2), prescaler, priority`.
    pub fn get_mode(&self, daq: u16) -> Result<[u8; 7], ErrorCode> {
        let l = self.list(daq)?;
        let flag = |on: bool, bit: u8| if on { bit } else { 0 };
        let mode = flag(l.selected, MODE_SELECTED)
            | flag(l.timestamp, MODE_TIMESTAMP)
            | flag(l.running, MODE_RUNNING);
        let e = l.event.to_le_bytes();
        Ok([mode, 0, 0, e[0], e[1], l.prescaler, l.priority])
    }

    /// The absolute ODT number of a list's first ODT.
    fn first_pid(&self, daq: usize) -> u8 {
        let n: usize = self.lists.iter().take(daq).map(|l| l.odts.len()).sum();
        // At most MAX_ODTS (64).
        n as u8
    }

    /// `ERR_DAQ_CONFIG` unless the list has ODTs and each fits one DTO.
    fn check(&self, daq: u16) -> Result<(), ErrorCode> {
        let list = self.list(daq)?;
        if list.odts.is_empty() {
            return Err(ErrorCode::DaqConfig);
        }
        for (j, odt) in list.odts.iter().enumerate() {
            let ts = if j == 0 && list.timestamp {
                TIMESTAMP_SIZE
            } else {
                0
            };
            let bytes: usize = odt.iter().map(|e| usize::from(e.size)).sum();
            if 1 + ts + bytes > MAX_DTO {
                return Err(ErrorCode::DaqConfig);
            }
        }
        Ok(())
    }

    /// START_STOP_DAQ_LIST: 0 stop, 1 start, 2 select; answers the list's first PID.
    pub fn start_stop(&mut self, mode: u8, daq: u16) -> Result<u8, ErrorCode> {
        if mode > 2 {
            return Err(ErrorCode::OutOfRange);
        }
        if mode != 0 {
            self.check(daq)?;
        }
        let first = self.first_pid(usize::from(daq));
        let list = self.list_mut(daq)?;
        match mode {
            0 => list.running = false,
            1 => {
                list.running = true;
                list.count = 0;
            }
            _ => list.selected = true,
        }
        Ok(first)
    }

    /// START_STOP_SYNCH: 0 stop all, 1 start selected, 2 stop selected.
    pub fn start_stop_synch(&mut self, mode: u8) -> Result<(), ErrorCode> {
        if mode > 2 {
            return Err(ErrorCode::OutOfRange);
        }
        for l in &mut self.lists {
            match mode {
                0 => l.running = false,
                1 if l.selected => {
                    l.running = true;
                    l.count = 0;
                }
                2 if l.selected => l.running = false,
                _ => {}
            }
            if mode == 0 || l.selected {
                l.selected = false;
            }
        }
        Ok(())
    }

    /// The DTOs of the running lists bound to `event`, in list and ODT order.
    pub fn sample(
        &mut self,
        now: Duration,
        event: u16,
        snapshot: &Snapshot,
        ecu: &impl XcpEcu,
    ) -> Vec<Vec<u8>> {
        let ts = (now.as_micros() as u32).to_le_bytes();
        let mut out = Vec::new();
        let mut pid = 0usize;
        for list in &mut self.lists {
            let first = pid;
            pid += list.odts.len();
            if !list.running || list.event != event {
                continue;
            }
            list.count = list.count.saturating_add(1);
            if list.count < list.prescaler {
                continue;
            }
            list.count = 0;
            for (j, odt) in list.odts.iter().enumerate() {
                let mut p = Vec::with_capacity(MAX_DTO);
                p.push((first + j) as u8);
                if j == 0 && list.timestamp {
                    p.extend_from_slice(&ts);
                }
                for e in odt.iter().filter(|e| e.size > 0) {
                    // Checked readable by WRITE_DAQ; a byte that is not reads as 0.
                    match memory::read(e.address, e.size, Some(snapshot), ecu) {
                        Ok(b) => p.extend_from_slice(&b),
                        Err(_) => p.extend(std::iter::repeat_n(0, usize::from(e.size))),
                    }
                }
                out.push(p);
            }
        }
        out
    }

    /// GET_DAQ_LIST_INFO of list `daq`: `properties, MAX_ODT, MAX_ODT_ENTRIES, FIXED_EVENT (2)`.
    pub fn list_info(&self, daq: u16) -> Result<[u8; 5], ErrorCode> {
        self.list(daq)?;
        // DAQ only, not predefined, event not fixed.
        Ok([0x04, MAX_ODTS_PER_LIST, MAX_ENTRIES_PER_ODT, 0, 0])
    }
}
