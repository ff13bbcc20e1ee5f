//! The operating-system settings a daemon's thread can ask for: the real-time FIFO scheduler
//! and the nice value (`ddct tcu --rt-priority/--nice`, the bench's ECU processes).

/// Puts the calling thread under the real-time FIFO scheduler at `priority` (1..=99), as a
/// bench ECU process would run; needs CAP_SYS_NICE (root). Under User-Mode Linux, where every
/// process of the guest shares one virtual CPU, it keeps a busy neighbour from delaying the
/// 10 ms loop (measured: 60 s of `ddct bench` went from a dozen spurious input timeouts to none).
/// The loops block on the bus or a timer every cycle, so they leave the CPU to the kernel.
pub fn set_realtime_priority(priority: i32) -> std::io::Result<()> {
    in_range("real-time priority", priority, RT_PRIORITIES)?;
    let param = libc::sched_param {
        sched_priority: priority,
    };
    // SAFETY: plain syscall on the calling thread (pid 0) with a valid parameter struct.
    os_result(unsafe { libc::sched_setscheduler(0, libc::SCHED_FIFO, &param) })
}

/// The SCHED_FIFO priorities (`--rt-priority`).
pub const RT_PRIORITIES: std::ops::RangeInclusive<i32> = 1..=99;
/// The nice values (`--nice`; lower is more CPU).
pub const NICE_VALUES: std::ops::RangeInclusive<i32> = -20..=19;

/// Sets the calling thread's nice value (the threads it starts afterwards inherit it).
pub fn set_nice(nice: i32) -> std::io::Result<()> {
    in_range("nice value", nice, NICE_VALUES)?;
    // SAFETY: plain syscall on the calling thread (who 0) with a value in range.
    os_result(unsafe { libc::setpriority(libc::PRIO_PROCESS, 0, nice) })
}

fn in_range(what: &str, v: i32, r: std::ops::RangeInclusive<i32>) -> std::io::Result<()> {
    if r.contains(&v) {
        Ok(())
    } else {
        Err(std::io::Error::new(
            std::io::ErrorKind::InvalidInput,
            format!("{what} {v} is outside {}..={}", r.start(), r.end()),
        ))
    }
}

/// A libc call's return code as a result (`errno` on failure).
fn os_result(rc: libc::c_int) -> std::io::Result<()> {
    if rc == 0 {
        Ok(())
    } else {
        Err(std::io::Error::last_os_error())
    }
}
