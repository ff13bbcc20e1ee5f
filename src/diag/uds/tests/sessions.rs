//! Sessions, the S3 timer, TesterPresent and the suppress bit.

use super::*;

#[test]
fn session_control_and_tester_present() {
    let mut r = Rig::new();
    assert_eq!(r.server.session(), Session::Default);
    assert_eq!(r.server.poll_timeout(), None);
    assert_eq!(
        r.req(&[0x10, 0x01]),
        Some(vec![0x50, 0x01, 0x00, 0x32, 0x01, 0xF4])
    );
    assert_eq!(r.req(&[0x3E, 0x00]), Some(vec![0x7E, 0x00]));
    assert_eq!(r.req(&[0x3E, 0x80]), None);
    // Suppressed: the session changes, no answer.
    assert_eq!(r.req(&[0x10, 0x83]), None);
    assert_eq!(r.server.session(), Session::Extended);
}

#[test]
fn s3_timeout_returns_to_default_and_locks() {
    let mut r = Rig::new();
    r.unlock();
    assert_eq!(
        r.req(&[0x31, 0x01, 0x02, 0x01, 0x01]),
        Some(vec![0x71, 0x01, 0x02, 0x01])
    );
    assert_eq!(r.server.poll_timeout(), Some(Duration::from_secs(5)));
    r.at_ms(4000);
    assert_eq!(r.req(&[0x3E, 0x80]), None);
    assert_eq!(r.server.poll_timeout(), Some(Duration::from_millis(9000)));
    r.server
        .handle_timeout(Duration::from_millis(8999), &mut r.ecu);
    assert_eq!(r.server.session(), Session::Extended);
    assert!(r.server.is_unlocked());
    r.server
        .handle_timeout(Duration::from_millis(9000), &mut r.ecu);
    assert_eq!(r.server.session(), Session::Default);
    assert!(!r.server.is_unlocked());
    assert_eq!(r.server.poll_timeout(), None);
    assert_eq!(r.ecu.stops, 1, "the running routine is stopped");
    r.at_ms(9000);
    assert_eq!(
        r.req(&[0x2E, 0x02, 0x00, 0x42, 0xC8, 0x00, 0x00]),
        nrc(0x2E, 0x7F)
    );
}

#[test]
fn a_session_change_locks() {
    let mut r = Rig::new();
    r.unlock();
    r.extended();
    assert!(!r.server.is_unlocked());
    assert_eq!(
        r.req(&[0x2E, 0x02, 0x00, 0x42, 0xC8, 0x00, 0x00]),
        nrc(0x2E, 0x33)
    );
}

#[test]
fn no_panic_on_any_short_request() {
    let mut r = Rig::new();
    r.unlock();
    for sid in 0..=255u8 {
        for len in 0..8usize {
            let mut req = vec![sid];
            req.extend((0..len).map(|i| (i as u8).wrapping_mul(0x35)));
            let _ = r.req(&req);
            let _ = r.func(&req);
        }
    }
}
