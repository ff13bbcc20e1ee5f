//! The classic CAN frame the buses carry: an 11- or 29-bit id, up to 8 data bytes or a remote
//! request. Implements `embedded_can::Frame` so it converts to and from any driver's frame type.

use embedded_can::{ExtendedId, Frame, Id, StandardId};
use thiserror::Error;

/// A classic CAN frame (no CAN FD).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct CanFrame {
    id: Id,
    dlc: u8,
    data: [u8; 8],
    remote: bool,
}

/// Why a frame could not be built.
#[derive(Debug, Clone, PartialEq, Eq, Error)]
pub enum FrameError {
    #[error("CAN id {id:#x} does not fit {bits} bits")]
    IdOutOfRange { id: u32, bits: u8 },
    #[error("{len} data bytes exceed the classic CAN maximum of 8")]
    TooLong { len: usize },
}

impl CanFrame {
    /// A data frame with a standard (11-bit) id.
    pub fn standard(id: u16, data: &[u8]) -> Result<Self, FrameError> {
        let sid = StandardId::new(id).ok_or(FrameError::IdOutOfRange {
            id: u32::from(id),
            bits: 11,
        })?;
        Self::with_id(Id::Standard(sid), data)
    }

    /// A data frame with an extended (29-bit) id.
    pub fn extended(id: u32, data: &[u8]) -> Result<Self, FrameError> {
        let eid = ExtendedId::new(id).ok_or(FrameError::IdOutOfRange { id, bits: 29 })?;
        Self::with_id(Id::Extended(eid), data)
    }

    /// A data frame with any id.
    pub fn with_id(id: Id, data: &[u8]) -> Result<Self, FrameError> {
        if data.len() > 8 {
            return Err(FrameError::TooLong { len: data.len() });
        }
        let mut d = [0u8; 8];
        d[..data.len()].copy_from_slice(data);
        Ok(Self {
            id,
            dlc: data.len() as u8,
            data: d,
            remote: false,
        })
    }

    /// A remote frame requesting `dlc` bytes.
    pub fn remote(id: Id, dlc: usize) -> Result<Self, FrameError> {
        if dlc > 8 {
            return Err(FrameError::TooLong { len: dlc });
        }
        Ok(Self {
            id,
            dlc: dlc as u8,
            data: [0; 8],
            remote: true,
        })
    }

    /// The id as a number (11 or 29 bits).
    pub fn raw_id(&self) -> u32 {
        match self.id {
            Id::Standard(s) => u32::from(s.as_raw()),
            Id::Extended(e) => e.as_raw(),
        }
    }

    /// The 11-bit id if this is a standard frame.
    pub fn standard_id(&self) -> Option<u16> {
        match self.id {
            Id::Standard(s) => Some(s.as_raw()),
            Id::Extended(_) => None,
        }
    }

    /// The data bytes (empty for a remote frame).
    pub fn bytes(&self) -> &[u8] {
        if self.remote {
            &[]
        } else {
            &self.data[..usize::from(self.dlc)]
        }
    }

    /// Converts any `embedded_can::Frame` (e.g. a socketcan frame) into this type.
    pub fn from_frame<F: Frame>(f: &F) -> Result<Self, FrameError> {
        if f.is_remote_frame() {
            Self::remote(f.id(), f.dlc())
        } else {
            Self::with_id(f.id(), f.data())
        }
    }
}

impl Frame for CanFrame {
    fn new(id: impl Into<Id>, data: &[u8]) -> Option<Self> {
        Self::with_id(id.into(), data).ok()
    }

    fn new_remote(id: impl Into<Id>, dlc: usize) -> Option<Self> {
        Self::remote(id.into(), dlc).ok()
    }

    fn is_extended(&self) -> bool {
        matches!(self.id, Id::Extended(_))
    }

    fn is_remote_frame(&self) -> bool {
        self.remote
    }

    fn id(&self) -> Id {
        self.id
    }

    fn dlc(&self) -> usize {
        usize::from(self.dlc)
    }

    fn data(&self) -> &[u8] {
        self.bytes()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn builds_and_rejects() {
        let f = CanFrame::standard(0x7FF, &[1, 2, 3]).unwrap();
        assert_eq!(
            (f.raw_id(), f.dlc(), f.bytes()),
            (0x7FF, 3, &[1u8, 2, 3][..])
        );
        assert!(!f.is_extended());
        assert_eq!(
            CanFrame::standard(0x800, &[]),
            Err(FrameError::IdOutOfRange {
                id: 0x800,
                bits: 11
            })
        );
        assert_eq!(
            CanFrame::standard(1, &[0; 9]),
            Err(FrameError::TooLong { len: 9 })
        );
        let e = CanFrame::extended(0x1FFF_FFFF, &[]).unwrap();
        assert!(e.is_extended());
        assert!(CanFrame::extended(0x2000_0000, &[]).is_err());
        let r = CanFrame::remote(e.id(), 4).unwrap();
        assert!(r.is_remote_frame());
        assert_eq!((r.dlc(), r.bytes().len()), (4, 0));
    }
}
