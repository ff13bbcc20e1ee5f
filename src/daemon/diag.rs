//! The TCU daemon's diagnostic side: the pure [`DiagStack`] (UDS on ISO-TP, XCP, the fault
//! memory) fed by the TCU shell, and the one thing the core cannot do, the fault memory file
//! (loaded at the start, saved atomically when it changed, at most every
//! [`FAULT_MEMORY_SAVE_EVERY`], and at the end).
//!
//! Control first: a diagnostic frame read while the TCU computes waits in a queue until the
//! cycle's control frames are out; then the requests are served and the responses sent.
//!
//! Its time is the shell's live time base (monotonic, the daemon's stalls taken out), on a
//! lockstep bench too: ISO-TP's STmin and timeouts and UDS's S3 are real-time rules of the
//! tester's, not simulated time.

use crate::can::CanFrame;
use crate::diag::dtc::memory::FaultMemory;
use crate::diag::isotp::Counters as IsoTpCounters;
use crate::diag::stack::{DiagConfig, DiagStack};
use crate::diag::store;
use crate::tcu::{Tcu, TcuConfig, TcuOutputs};
use serde::Serialize;
use std::collections::VecDeque;
use std::path::PathBuf;
use std::time::Duration;
use tokio::time::Instant;

/// The diagnostic side of the daemon.
#[derive(Debug, Clone, Default)]
pub struct DiagDaemonConfig {
    pub diag: DiagConfig,
    /// The fault memory file (loaded at the start, saved atomically when it changed, at most
    /// every [`FAULT_MEMORY_SAVE_EVERY`], and at the end); `None`: kept in memory only.
    pub fault_memory: Option<PathBuf>,
}

/// The fault memory is saved at most this often while it changes (and always at the end).
pub const FAULT_MEMORY_SAVE_EVERY: Duration = Duration::from_secs(1);

/// What the diagnostic side did.
#[derive(Debug, Clone, Serialize)]
pub struct DiagReport {
    /// Diagnostic frames received (UDS and XCP), dropped unserved (a flood: more than
    /// `MAX_PENDING` waiting) and sent.
    pub frames_received: u64,
    pub frames_dropped: u64,
    pub frames_sent: u64,
    /// The ISO-TP transport's counts (dropped frames by cause, timeouts).
    pub isotp: IsoTpCounters,
    /// ECU resets performed.
    pub resets: u64,
    /// Fault memory saves, and saves that failed (the daemon goes on; the next change retries).
    pub fault_memory_saves: u64,
    pub fault_memory_save_errors: u64,
    /// The fault memory file found corrupt at the start and set aside (its new name).
    pub fault_memory_set_aside: Option<PathBuf>,
}

/// Diagnostic frames waiting to be served at most (a tester sends one request at a time, an XCP
/// master one command; more is a flood).
pub(super) const MAX_PENDING: usize = 1024;

/// The diagnostic side's state in the shell.
pub(super) struct DiagShell {
    pub(super) core: DiagStack,
    /// The calibration a reset restarts the core with.
    tcu_cfg: TcuConfig,
    fault_memory: Option<PathBuf>,
    last_save: Option<Instant>,
    pub(super) received: u64,
    pub(super) sent: u64,
    /// Frames received, not yet served.
    pending: VecDeque<CanFrame>,
    /// Frames dropped with [`MAX_PENDING`] waiting.
    dropped: u64,
    resets: u64,
    saves: u64,
    save_errors: u64,
    set_aside: Option<PathBuf>,
}

impl DiagShell {
    /// The diagnostic side with its fault memory file loaded: a missing file is an empty
    /// memory; a corrupt one is reported, set aside and replaced by an empty memory; a file
    /// that cannot be read at all is an error (the daemon does not start on it).
    pub(super) fn open(
        cfg: &DiagDaemonConfig,
        tcu_cfg: &TcuConfig,
    ) -> Result<Self, store::StoreError> {
        let (memory, set_aside) = match &cfg.fault_memory {
            Some(path) => {
                let (memory, corrupt) = store::load(path)?;
                if let Some(c) = &corrupt {
                    tracing::warn!(
                        "fault memory {} is corrupt ({}): set aside as {}, starting empty",
                        c.path.display(),
                        c.reason,
                        c.moved_to.display()
                    );
                }
                (memory, corrupt.map(|c| c.moved_to))
            }
            None => (FaultMemory::default(), None),
        };
        // A run of the daemon is an operation cycle (ISO 14229-1 annex D).
        let mut memory = memory;
        memory.start_operation_cycle();
        Ok(DiagShell {
            core: DiagStack::new(cfg.diag.clone(), memory),
            tcu_cfg: tcu_cfg.clone(),
            fault_memory: cfg.fault_memory.clone(),
            last_save: None,
            received: 0,
            sent: 0,
            pending: VecDeque::new(),
            dropped: 0,
            resets: 0,
            saves: 0,
            save_errors: 0,
            set_aside,
        })
    }

    /// A received diagnostic frame: queued, served after the cycle's control frames are out
    /// ([`Self::serve_pending`]). Beyond [`MAX_PENDING`] waiting frames (a flood on the
    /// diagnostic ids) a frame is dropped and counted.
    pub(super) fn on_frame(&mut self, frame: CanFrame) {
        self.received += 1;
        if self.pending.len() < MAX_PENDING {
            self.pending.push_back(frame);
        } else {
            self.dropped += 1;
        }
    }

    /// Serves the queued diagnostic frames at `now`, in arrival order.
    pub(super) fn serve_pending(&mut self, now: Duration, tcu: &mut Tcu) {
        while let Some(f) = self.pending.pop_front() {
            self.core.handle_frame(now, &f, tcu);
        }
    }

    /// After a TCU step.
    pub(super) fn after_step(
        &mut self,
        now: Duration,
        core_now: Duration,
        out: &TcuOutputs,
        tcu: &mut Tcu,
    ) {
        self.core.after_step(now, core_now, out, tcu);
    }

    /// An ECUReset whose response is out: the core restarts from the calibration it started
    /// with (a calibration written on the bus lives in RAM, as an ECU's would without a flash
    /// write) and keeps its learned kiss points; the fault memory starts a new operation cycle.
    pub(super) fn reset_if_due(&mut self, now: Duration, tcu: &mut Tcu) {
        if self.core.take_reset().is_none() {
            return;
        }
        let learned = tcu.learned_kiss_points();
        *tcu = Tcu::new(self.tcu_cfg.clone(), now);
        tcu.restore_learned_kiss_points(learned);
        self.core.restarted();
        self.resets += 1;
        tracing::info!(
            "ECU reset: TCU core restarted at {:.3} s",
            now.as_secs_f64()
        );
    }

    /// Saves the fault memory when it changed and the last save is [`FAULT_MEMORY_SAVE_EVERY`]
    /// old (`force`: at the end, whatever the time). A failed save is logged and counted; the
    /// memory stays dirty, so the next one retries.
    pub(super) fn save_if_due(&mut self, force: bool) {
        let Some(path) = &self.fault_memory else {
            return;
        };
        if !self.core.memory().is_dirty() {
            return;
        }
        let now = Instant::now();
        if !force
            && self
                .last_save
                .is_some_and(|t| now - t < FAULT_MEMORY_SAVE_EVERY)
        {
            return;
        }
        self.last_save = Some(now);
        match store::save(path, self.core.memory()) {
            Ok(()) => {
                self.saves += 1;
                self.core.memory_saved();
            }
            Err(e) => {
                self.save_errors += 1;
                tracing::warn!("fault memory not saved: {e}");
            }
        }
    }

    pub(super) fn report(&self) -> DiagReport {
        DiagReport {
            frames_received: self.received,
            frames_dropped: self.dropped,
            frames_sent: self.sent,
            isotp: *self.core.isotp_counters(),
            resets: self.resets,
            fault_memory_saves: self.saves,
            fault_memory_save_errors: self.save_errors,
            fault_memory_set_aside: self.set_aside.clone(),
        }
    }
}
