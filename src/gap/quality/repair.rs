//! What the diagnosis does with a logger's artefacts: the samples of a spike or a dropout are
//! not readings. In the record the model takes its inputs from (speeds, torques for the friction
//! power, temperatures for the disk estimate) they are bridged by a straight line between the
//! good samples on either side; in every comparison with the model — fits, noise floors,
//! validation scores — they are left out.

use super::profile::Profile;
use crate::records::dataset::Dataset;
use std::borrow::Cow;

/// `d` with the spike and dropout samples of its checked channels (its `profile`'s) bridged:
/// the record itself when it has none.
pub fn repaired<'a>(d: &'a Dataset, profile: &Profile) -> Cow<'a, Dataset> {
    let mut record = Cow::Borrowed(d);
    for (c, bad) in profile.bad() {
        let Some(v) = d.get(c) else { continue };
        let mut w = v.to_vec();
        bridge(&mut w, bad);
        record.to_mut().set(c, w);
    }
    record
}

/// Replaces the samples `bad` (ascending) of `v` by the straight line between the nearest good
/// samples on either side (the nearest good sample at a record's end).
fn bridge(v: &mut [f64], bad: &[usize]) {
    let mut i = 0;
    while i < bad.len() {
        let start = bad[i];
        let mut end = start;
        while i + 1 < bad.len() && bad[i + 1] == end + 1 {
            i += 1;
            end += 1;
        }
        i += 1;
        let before = start.checked_sub(1).map(|k| v[k]);
        let after = v.get(end + 1).copied();
        let (a, b) = match (before, after) {
            (Some(a), Some(b)) => (a, b),
            (Some(a), None) => (a, a),
            (None, Some(b)) => (b, b),
            (None, None) => return,
        };
        let n = (end - start + 2) as f64;
        for (j, x) in v[start..=end].iter_mut().enumerate() {
            *x = a + (b - a) * (j + 1) as f64 / n;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn runs_are_bridged_by_a_straight_line_and_ends_by_the_nearest_sample() {
        let mut v = vec![0.0, 10.0, -1.0, -1.0, -1.0, 50.0, 60.0, -1.0];
        bridge(&mut v, &[2, 3, 4, 7]);
        assert_eq!(v, vec![0.0, 10.0, 20.0, 30.0, 40.0, 50.0, 60.0, 60.0]);
        let mut w = vec![-1.0, 5.0];
        bridge(&mut w, &[0]);
        assert_eq!(w, vec![5.0, 5.0]);
    }
}
