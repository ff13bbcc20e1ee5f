//! The fault memory's file (`ddct tcu --fault-memory PATH`; ISO 14229-1 annex D leaves the
//! non-volatile storage of the DTC status and records to the server): the only file IO in
//! `diag`, called by the daemon's shell alone.
//!
//! - [`load`]: a missing file is an empty memory; a corrupt one (not the JSON of
//!   [`FaultMemory::to_bytes`], another format version) is renamed to `PATH.corrupt` and
//!   reported in a [`CorruptReport`], and the memory starts empty: it does not stop the daemon.
//! - [`save`]: atomic. A temporary file in the same directory is written and fsynced, renamed
//!   over `PATH`, then the directory is fsynced so the rename itself is durable. A failed save
//!   leaves the old file and removes the temporary one.

use std::fs::{self, File, OpenOptions};
use std::io::{self, Write};
use std::path::{Path, PathBuf};

use crate::diag::dtc::memory::FaultMemory;
use crate::diag::dtc::DtcError;

/// Why the fault memory's file could not be read or written.
#[derive(Debug, thiserror::Error)]
pub enum StoreError {
    #[error("cannot read the fault memory {path}")]
    Read {
        path: PathBuf,
        #[source]
        source: io::Error,
    },
    #[error("cannot set the corrupt fault memory {path} aside as {to}")]
    SetAside {
        path: PathBuf,
        to: PathBuf,
        #[source]
        source: io::Error,
    },
    #[error("cannot serialize the fault memory for {path}")]
    Serialize {
        path: PathBuf,
        #[source]
        source: DtcError,
    },
    #[error("cannot write the fault memory {path}")]
    Write {
        path: PathBuf,
        #[source]
        source: io::Error,
    },
}

/// A corrupt fault memory file that was set aside.
#[derive(Debug)]
pub struct CorruptReport {
    /// The file that was corrupt.
    pub path: PathBuf,
    /// Where it is now (`PATH.corrupt`).
    pub moved_to: PathBuf,
    /// What was wrong with it.
    pub reason: DtcError,
}

/// `PATH.corrupt`.
pub(crate) fn corrupt_path(path: &Path) -> PathBuf {
    let mut s = path.as_os_str().to_owned();
    s.push(".corrupt");
    PathBuf::from(s)
}

/// The fault memory in `path` (not dirty), or an empty one if there is no file or it is
/// corrupt (then set aside and reported).
pub fn load(path: &Path) -> Result<(FaultMemory, Option<CorruptReport>), StoreError> {
    let bytes = match fs::read(path) {
        Ok(b) => b,
        Err(e) if e.kind() == io::ErrorKind::NotFound => return Ok((FaultMemory::new(), None)),
        Err(source) => {
            return Err(StoreError::Read {
                path: path.to_owned(),
                source,
            })
        }
    };
    match FaultMemory::from_bytes(&bytes) {
        Ok(memory) => Ok((memory, None)),
        Err(reason) => {
            let to = corrupt_path(path);
            fs::rename(path, &to).map_err(|source| StoreError::SetAside {
                path: path.to_owned(),
                to: to.clone(),
                source,
            })?;
            let report = CorruptReport {
                path: path.to_owned(),
                moved_to: to,
                reason,
            };
            Ok((FaultMemory::new(), Some(report)))
        }
    }
}

/// Writes `memory` to `path` atomically (it does not mark it saved: the caller does, on
/// success).
pub fn save(path: &Path, memory: &FaultMemory) -> Result<(), StoreError> {
    let bytes = memory.to_bytes().map_err(|source| StoreError::Serialize {
        path: path.to_owned(),
        source,
    })?;
    let write_err = |source| StoreError::Write {
        path: path.to_owned(),
        source,
    };
    let dir = match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d.to_owned(),
        _ => PathBuf::from("."),
    };
    let name = path
        .file_name()
        .ok_or_else(|| write_err(io::Error::other("the path names no file")))?;
    let mut tmp_name = std::ffi::OsString::from(".");
    tmp_name.push(name);
    tmp_name.push(format!(".tmp{}", std::process::id()));
    let tmp = dir.join(tmp_name);
    let result = write_synced(&tmp, &bytes).and_then(|()| fs::rename(&tmp, path));
    if let Err(e) = result {
        let _ = fs::remove_file(&tmp);
        return Err(write_err(e));
    }
    File::open(&dir)
        .and_then(|d| d.sync_all())
        .map_err(write_err)
}

/// Creates `tmp` (replacing a leftover of a crashed save), writes `bytes`, fsyncs.
fn write_synced(tmp: &Path, bytes: &[u8]) -> io::Result<()> {
    let mut f = OpenOptions::new()
        .write(true)
        .create(true)
        .truncate(true)
        .open(tmp)?;
    f.write_all(bytes)?;
    f.sync_all()
}

#[cfg(test)]
mod tests {
    use std::time::Duration;

    use super::*;
    use crate::can::messages::{FaultCode, TcuState};
    use crate::diag::values::Snapshot;
    use crate::model::gear::Gear;

    /// A fresh directory under the system's temporary directory.
    fn temp_dir(name: &str) -> PathBuf {
        let d = std::env::temp_dir().join(format!("ddct-store-{name}-{}", std::process::id()));
        let _ = fs::remove_dir_all(&d);
        fs::create_dir_all(&d).unwrap();
        d
    }

    fn names(dir: &Path) -> Vec<String> {
        let mut v: Vec<String> = fs::read_dir(dir)
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .collect();
        v.sort();
        v
    }

    fn failed_memory() -> FaultMemory {
        let s = Snapshot {
            t_s: 1.0,
            state: TcuState::Neutral,
            fault: FaultCode::SensorsCrc,
            gear_active: Gear::N,
            theta_est_c: [40.0, 41.0],
            t_ref_nm: [0.0; 2],
            x_ref_mm: [0.0; 2],
            x_mm: [0.0; 2],
            kiss_mm: [4.0; 2],
            engine_rpm: 800.0,
            shaft_rpm: [0.0; 2],
            out_rpm: 0.0,
            pedal_pct: 0.0,
            housing_c: 30.0,
        };
        let mut m = FaultMemory::new();
        m.update(Duration::ZERO, FaultCode::SensorsCrc, true, &s);
        m
    }

    #[test]
    fn missing_file_is_an_empty_memory() {
        let d = temp_dir("missing");
        let (m, report) = load(&d.join("faults.json")).unwrap();
        assert_eq!(m, FaultMemory::new());
        assert!(report.is_none());
        fs::remove_dir_all(&d).unwrap();
    }

    #[test]
    fn round_trip_leaves_no_temporary_file() {
        let d = temp_dir("round-trip");
        let path = d.join("faults.json");
        let m = failed_memory();
        save(&path, &m).unwrap();
        save(&path, &m).unwrap();
        assert_eq!(names(&d), vec!["faults.json".to_string()]);
        let (back, report) = load(&path).unwrap();
        assert!(report.is_none());
        assert_eq!(back.status_of(FaultCode::SensorsCrc), Some(0x27));
        assert_eq!(back.to_bytes().unwrap(), m.to_bytes().unwrap());
        fs::remove_dir_all(&d).unwrap();
    }

    #[test]
    fn corrupt_file_is_set_aside_and_reported() {
        let d = temp_dir("corrupt");
        let path = d.join("faults.json");
        fs::write(&path, b"{\"version\": 1, \"dtcs\": [").unwrap();
        let (m, report) = load(&path).unwrap();
        assert_eq!(m, FaultMemory::new());
        let report = report.unwrap();
        assert_eq!(report.moved_to, d.join("faults.json.corrupt"));
        assert!(matches!(report.reason, DtcError::Json(_)));
        assert_eq!(names(&d), vec!["faults.json.corrupt".to_string()]);
        // The daemon then saves an empty memory beside it.
        save(&path, &m).unwrap();
        assert_eq!(names(&d), vec!["faults.json", "faults.json.corrupt"]);
        fs::remove_dir_all(&d).unwrap();
    }

    #[test]
    fn errors_name_the_path() {
        let d = temp_dir("errors");
        let path = d.join("no-such-dir").join("faults.json");
        let e = save(&path, &FaultMemory::new()).unwrap_err();
        assert!(e.to_string().contains("no-such-dir"), "{e}");
        assert!(matches!(e, StoreError::Write { .. }));
        // A directory where the file should be: reading fails with the path.
        let e = load(&d).unwrap_err();
        assert!(matches!(e, StoreError::Read { .. }), "{e}");
        assert!(names(&d).is_empty());
        fs::remove_dir_all(&d).unwrap();
    }
}
