//! `ddct diag`: a UDS tester for people without a python one (issue 16) — read DIDs, read and
//! clear the fault memory, run the kiss-point routine, write a calibration behind SecurityAccess
//! — and the A2L file of the TCU's XCP slave. It speaks the bytes of docs/diagnostics.md itself
//! (the client side is written apart from the server's code) through [`UdsTester`].

use super::args::open_can;
use super::runtime;
use anyhow::{bail, Context};
use clap::{Args, Subcommand};
use ddct::bench::tester::{TesterTiming, UdsTester};
use ddct::can::messages::ids;
use ddct::can::socketcan::SocketCanBus;
use ddct::diag::dtc::{self, Dtc};
use ddct::diag::isotp::IsoTpConfig;
use ddct::diag::values::{Calibration, Measurement};
use std::path::PathBuf;
use std::process::ExitCode;
use std::time::{Duration, Instant};

#[derive(Debug, Subcommand)]
pub enum DiagCmd {
    /// Read data identifiers: numbers (0xF195, 0x0100) or names (Clutch1TempEst,
    /// control.clutch_kp_per_s, LearnedKiss1, Serial, Version, SystemName).
    ReadDid(ReadDidArgs),
    /// List the fault memory's DTCs with their status, snapshot and extended data.
    Dtc(DtcArgs),
    /// Clear the fault memory (all DTCs, or one).
    Clear(ClearArgs),
    /// Run the kiss-point adaptation routine on a clutch and print the learned kiss point.
    KissPoint(KissArgs),
    /// Write a calibration (extended session, SecurityAccess level 1 unlocked first).
    WriteCal(WriteCalArgs),
    /// Reset the TCU (ECUReset hard reset, from the extended session): the core restarts from its
    /// calibration file; the fault memory and learned kiss points are kept.
    Reset(BusArgs),
    /// Write the A2L file of the TCU's XCP slave (measurements, calibrations, XCP on CAN).
    A2l(A2lArgs),
}

#[derive(Debug, Args)]
pub struct BusArgs {
    /// CAN interface the TCU is on (e.g. vcan0).
    #[arg(long)]
    iface: String,
    /// Seconds to wait for a response (P2; 5 s after a "response pending").
    #[arg(long, default_value_t = 1.0, value_parser = positive_seconds)]
    timeout: f64,
}

#[derive(Debug, Args)]
pub struct ReadDidArgs {
    #[command(flatten)]
    bus: BusArgs,
    /// The identifiers.
    #[arg(required = true, value_parser = parse_did)]
    dids: Vec<u16>,
}

#[derive(Debug, Args)]
pub struct DtcArgs {
    #[command(flatten)]
    bus: BusArgs,
    /// Status mask (ISO 14229-1 status bits; 0xFF: every DTC stored).
    #[arg(long, default_value = "0xFF", value_parser = parse_u8)]
    mask: u8,
}

#[derive(Debug, Args)]
pub struct ClearArgs {
    #[command(flatten)]
    bus: BusArgs,
    /// One DTC (3 bytes, e.g. 0xC10000); default: all (0xFFFFFF).
    #[arg(long, default_value = "0xFFFFFF", value_parser = parse_dtc)]
    dtc: u32,
}

#[derive(Debug, Args)]
pub struct KissArgs {
    #[command(flatten)]
    bus: BusArgs,
    /// The clutch (1: odd gears, 2: even gears).
    #[arg(long, value_parser = clap::value_parser!(u8).range(1..=2))]
    clutch: u8,
    /// Seconds to wait for the routine to finish.
    #[arg(long, default_value_t = 60.0, value_parser = positive_seconds)]
    wait: f64,
}

#[derive(Debug, Args)]
pub struct WriteCalArgs {
    #[command(flatten)]
    bus: BusArgs,
    /// The calibration's key (e.g. control.clutch_kp_per_s).
    #[arg(value_parser = parse_calibration)]
    name: Calibration,
    /// The value (in the key's unit).
    value: f32,
}

#[derive(Debug, Args)]
pub struct A2lArgs {
    /// Where to write the A2L file.
    #[arg(long)]
    out: PathBuf,
}

fn positive_seconds(s: &str) -> Result<f64, String> {
    match s.parse::<f64>() {
        Ok(v) if v.is_finite() && v > 0.0 => Ok(v),
        _ => Err(format!("{s:?} is not a positive number of seconds")),
    }
}

fn parse_hex(s: &str) -> Option<u32> {
    let h = s.strip_prefix("0x").or_else(|| s.strip_prefix("0X"))?;
    u32::from_str_radix(h, 16).ok()
}

fn parse_u8(s: &str) -> Result<u8, String> {
    parse_hex(s)
        .or_else(|| s.parse().ok())
        .and_then(|v| u8::try_from(v).ok())
        .ok_or_else(|| format!("{s:?} is not a byte (0..=255 or 0x00..=0xFF)"))
}

fn parse_dtc(s: &str) -> Result<u32, String> {
    parse_hex(s)
        .filter(|v| *v <= 0xFF_FFFF)
        .ok_or_else(|| format!("{s:?} is not a 3-byte DTC in hex (e.g. 0xC10000)"))
}

/// The identification DIDs of docs/diagnostics.md.
const IDENTIFICATION: [(u16, &str); 3] = [
    (0xF18C, "Serial"),
    (0xF195, "Version"),
    (0xF197, "SystemName"),
];
const MEASUREMENT_DID: u16 = 0x0100;
const CALIBRATION_DID: u16 = 0x0200;
const LEARNED_KISS_DID: u16 = 0x0300;
/// DIDs in each block of the table (256).
const DID_BLOCK: u16 = 1 << 8;

fn parse_did(s: &str) -> Result<u16, String> {
    if let Some(v) = parse_hex(s) {
        return u16::try_from(v).map_err(|_| format!("{s:?} is not a 2-byte DID"));
    }
    let by_name = IDENTIFICATION
        .iter()
        .find(|(_, n)| n.eq_ignore_ascii_case(s))
        .map(|(d, _)| *d)
        .or_else(|| {
            Measurement::ALL
                .iter()
                .position(|m| m.meta().name == s)
                .map(|i| MEASUREMENT_DID + i as u16)
        })
        .or_else(|| {
            Calibration::ALL
                .iter()
                .position(|c| c.meta().name == s)
                .map(|i| CALIBRATION_DID + i as u16)
        })
        .or(match s {
            "LearnedKiss1" => Some(LEARNED_KISS_DID),
            "LearnedKiss2" => Some(LEARNED_KISS_DID + 1),
            _ => None,
        });
    by_name.ok_or_else(|| {
        format!("{s:?} is neither a DID in hex (0x0100) nor a known name (see docs/diagnostics.md)")
    })
}

fn parse_calibration(s: &str) -> Result<Calibration, String> {
    Calibration::ALL
        .into_iter()
        .find(|c| c.meta().name == s)
        .ok_or_else(|| {
            let names: Vec<&str> = Calibration::ALL.iter().map(|c| c.meta().name).collect();
            format!(
                "{s:?} is not a calibration on the bus; these are: {}",
                names.join(", ")
            )
        })
}

/// A DID's name, unit and how its bytes read.
fn describe(did: u16, data: &[u8]) -> String {
    if let Some((_, name)) = IDENTIFICATION.iter().find(|(d, _)| *d == did) {
        return format!("{name} = {:?}", String::from_utf8_lossy(data).trim_end());
    }
    let (name, unit) = match did {
        d if (MEASUREMENT_DID..MEASUREMENT_DID + DID_BLOCK).contains(&d) => Measurement::ALL
            .get(usize::from(d - MEASUREMENT_DID))
            .map(|m| (m.meta().name.to_string(), m.meta().unit)),
        d if (CALIBRATION_DID..CALIBRATION_DID + DID_BLOCK).contains(&d) => Calibration::ALL
            .get(usize::from(d - CALIBRATION_DID))
            .map(|c| (c.meta().name.to_string(), c.meta().unit)),
        d if d == LEARNED_KISS_DID || d == LEARNED_KISS_DID + 1 => {
            Some((format!("LearnedKiss{}", d - LEARNED_KISS_DID + 1), "mm"))
        }
        _ => None,
    }
    .unwrap_or_else(|| (format!("DID {did:#06x}"), ""));
    match <[u8; 4]>::try_from(data) {
        Ok(b) => format!("{name} = {} {unit}", f32::from_be_bytes(b)),
        Err(_) => format!("{name} = {}", hex(data)),
    }
}

fn hex(b: &[u8]) -> String {
    b.iter()
        .map(|x| format!("{x:02x}"))
        .collect::<Vec<_>>()
        .join(" ")
}

/// The ISO 14229-1 status bits by name.
fn status_bits(s: u8) -> String {
    const NAMES: [&str; 8] = [
        "testFailed",
        "testFailedThisOperationCycle",
        "pendingDTC",
        "confirmedDTC",
        "testNotCompletedSinceLastClear",
        "testFailedSinceLastClear",
        "testNotCompletedThisOperationCycle",
        "warningIndicatorRequested",
    ];
    let set: Vec<&str> = (0..8)
        .filter(|i| s & (1 << i) != 0)
        .map(|i| NAMES[i])
        .collect();
    format!("{s:#04x} [{}]", set.join(", "))
}

type Tester = UdsTester<SocketCanBus>;

/// Opens the tester on `a.iface`, listening to the TCU's responses only.
fn tester(a: &BusArgs) -> anyhow::Result<Tester> {
    let bus = open_can(&a.iface)?;
    bus.set_filter_ids(&[ids::TCU_DIAG_RESP])?;
    let p2 = Duration::from_secs_f64(a.timeout);
    Ok(UdsTester::new(
        bus,
        IsoTpConfig::default(),
        TesterTiming {
            p2,
            p2_star: p2.max(Duration::from_secs(5)),
        },
    ))
}

/// A request whose response must be positive (`SID + 0x40`); a negative one is an error naming
/// its NRC.
async fn positive(t: &mut Tester, req: &[u8]) -> anyhow::Result<Vec<u8>> {
    let resp = t.request(req).await?;
    match resp.as_slice() {
        [0x7F, sid, nrc, ..] => bail!(
            "negative response to {sid:#04x}: NRC {nrc:#04x} ({})",
            nrc_name(*nrc)
        ),
        [sid, ..] if Some(sid.wrapping_sub(0x40)) == req.first().copied() => Ok(resp),
        _ => bail!("unexpected response {} to {}", hex(&resp), hex(req)),
    }
}

fn nrc_name(nrc: u8) -> &'static str {
    match nrc {
        0x11 => "serviceNotSupported",
        0x12 => "subFunctionNotSupported",
        0x13 => "incorrectMessageLengthOrInvalidFormat",
        0x22 => "conditionsNotCorrect",
        0x24 => "requestSequenceError",
        0x31 => "requestOutOfRange",
        0x33 => "securityAccessDenied",
        0x35 => "invalidKey",
        0x36 => "exceededNumberOfAttempts",
        0x37 => "requiredTimeDelayNotExpired",
        0x7E => "subFunctionNotSupportedInActiveSession",
        0x7F => "serviceNotSupportedInActiveSession",
        _ => "see ISO 14229-1 Annex A",
    }
}

pub fn run(c: DiagCmd) -> anyhow::Result<ExitCode> {
    if let DiagCmd::A2l(a) = &c {
        std::fs::write(&a.out, ddct::diag::a2l::a2l())
            .with_context(|| format!("writing {}", a.out.display()))?;
        eprintln!("wrote {}", a.out.display());
        return Ok(ExitCode::SUCCESS);
    }
    let rt = runtime()?;
    rt.block_on(async {
        match c {
            DiagCmd::ReadDid(a) => read_dids(&a).await,
            DiagCmd::Dtc(a) => list_dtcs(&a).await,
            DiagCmd::Clear(a) => clear(&a).await,
            DiagCmd::KissPoint(a) => kiss_point(&a).await,
            DiagCmd::WriteCal(a) => write_cal(&a).await,
            DiagCmd::Reset(a) => reset(&a).await,
            DiagCmd::A2l(_) => Ok(()),
        }
    })?;
    Ok(ExitCode::SUCCESS)
}

async fn read_dids(a: &ReadDidArgs) -> anyhow::Result<()> {
    let mut t = tester(&a.bus)?;
    for did in &a.dids {
        let resp = positive(&mut t, &[0x22, (did >> 8) as u8, *did as u8]).await?;
        let data = resp.get(3..).unwrap_or_default();
        println!("{did:#06x} {}", describe(*did, data));
    }
    Ok(())
}

async fn list_dtcs(a: &DtcArgs) -> anyhow::Result<()> {
    let mut t = tester(&a.bus)?;
    let resp = positive(&mut t, &[0x19, 0x02, a.mask]).await?;
    let records = resp.get(3..).unwrap_or_default();
    if records.is_empty() {
        println!("no DTC matches status mask {:#04x}", a.mask);
    }
    for r in records.chunks_exact(4) {
        let dtc = Dtc::from_bytes([r[0], r[1], r[2]]);
        // The SAE form and the TCU fault code it stands for (the TCU's own table).
        let fault = dtc::TABLE
            .iter()
            .find(|(_, d)| *d == dtc)
            .map_or(String::new(), |(f, _)| format!(" {}", f.label()));
        println!(
            "DTC {:#08x} {dtc}{fault} status {}",
            dtc.value(),
            status_bits(r[3])
        );
        let req = [0x19, 0x04, r[0], r[1], r[2], 0x01];
        if let Ok(snap) = positive(&mut t, &req).await {
            print_snapshot(&snap);
        }
        let req = [0x19, 0x06, r[0], r[1], r[2], 0xFF];
        if let Ok(ext) = positive(&mut t, &req).await {
            println!("  extended data: {}", hex(ext.get(6..).unwrap_or_default()));
        }
    }
    Ok(())
}

/// `59 04 DTC(3) status record count (DID(2) value(4))*`.
fn print_snapshot(snap: &[u8]) {
    let Some(body) = snap.get(8..) else {
        return;
    };
    println!(
        "  snapshot record {:#04x}:",
        snap.get(6).copied().unwrap_or(0)
    );
    for item in body.chunks_exact(6) {
        let did = u16::from_be_bytes([item[0], item[1]]);
        println!("    {}", describe(did, &item[2..]));
    }
}

async fn clear(a: &ClearArgs) -> anyhow::Result<()> {
    let mut t = tester(&a.bus)?;
    let d = a.dtc.to_be_bytes();
    positive(&mut t, &[0x14, d[1], d[2], d[3]]).await?;
    println!("cleared {:#08x}", a.dtc);
    Ok(())
}

async fn kiss_point(a: &KissArgs) -> anyhow::Result<()> {
    let mut t = tester(&a.bus)?;
    positive(&mut t, &[0x10, 0x03]).await?;
    positive(&mut t, &[0x31, 0x01, 0x02, 0x01, a.clutch]).await?;
    let end = Instant::now() + Duration::from_secs_f64(a.wait);
    loop {
        tokio::time::sleep(Duration::from_millis(500)).await;
        positive(&mut t, &[0x3E, 0x00]).await?;
        let r = positive(&mut t, &[0x31, 0x03, 0x02, 0x01]).await?;
        match r.get(4..).unwrap_or_default() {
            [2, k0, k1, k2, k3, ..] => {
                let kiss = f32::from_be_bytes([*k0, *k1, *k2, *k3]);
                println!("clutch {}: learned kiss point {kiss:.3} mm", a.clutch);
                return Ok(());
            }
            [3, reason, ..] => bail!("the routine was aborted (reason {reason})"),
            [1, ..] | [0, ..] if Instant::now() < end => continue,
            other => bail!(
                "the routine did not finish within {} s (status {})",
                a.wait,
                hex(other)
            ),
        }
    }
}

/// The SecurityAccess key of docs/diagnostics.md.
fn key_of(seed: u32) -> u32 {
    (seed ^ 0x4444_5443).rotate_left(7)
}

async fn write_cal(a: &WriteCalArgs) -> anyhow::Result<()> {
    let mut t = tester(&a.bus)?;
    positive(&mut t, &[0x10, 0x03]).await?;
    let seed = positive(&mut t, &[0x27, 0x01]).await?;
    let Some(s) = seed.get(2..6).and_then(|b| <[u8; 4]>::try_from(b).ok()) else {
        bail!("short seed response {}", hex(&seed));
    };
    let s = u32::from_be_bytes(s);
    if s != 0 {
        let k = key_of(s).to_be_bytes();
        positive(&mut t, &[0x27, 0x02, k[0], k[1], k[2], k[3]]).await?;
    }
    let i = Calibration::ALL
        .iter()
        .position(|c| *c == a.name)
        .unwrap_or(0) as u16;
    let did = CALIBRATION_DID + i;
    let v = a.value.to_be_bytes();
    positive(
        &mut t,
        &[0x2E, (did >> 8) as u8, did as u8, v[0], v[1], v[2], v[3]],
    )
    .await?;
    println!("{} = {}", a.name.meta().name, a.value);
    Ok(())
}

async fn reset(a: &BusArgs) -> anyhow::Result<()> {
    let mut t = tester(a)?;
    // A hard reset is refused in the default session (docs/diagnostics.md).
    positive(&mut t, &[0x10, 0x03]).await?;
    positive(&mut t, &[0x11, 0x01]).await?;
    println!("reset");
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_key_is_the_documented_rotation() {
        // seed 0x11223344: XOR 0x44445443 = 0x55666707; rotated left by 7 = 0xb33383aa.
        let x: u32 = 0x1122_3344 ^ 0x4444_5443;
        assert_eq!(x, 0x5566_6707);
        assert_eq!(key_of(0x1122_3344), 0xB333_83AA);
    }

    #[test]
    fn dids_by_number_and_name() {
        assert_eq!(parse_did("0xF195"), Ok(0xF195));
        assert_eq!(parse_did("Version"), Ok(0xF195));
        assert_eq!(parse_did("Clutch2TempEst"), Ok(0x0101));
        assert_eq!(parse_did("compensation.slip"), Ok(0x0207));
        assert_eq!(parse_did("LearnedKiss2"), Ok(0x0301));
        assert!(parse_did("nope").is_err());
        assert!(parse_did("0x10000").is_err());
    }
}
