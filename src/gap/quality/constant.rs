//! A channel that never changes: every finite sample the same value.

/// The value of `v` when every finite sample holds it (and there are at least two), else `None`.
pub fn value(v: &[f64]) -> Option<f64> {
    let mut finite = v.iter().copied().filter(|x| x.is_finite());
    let first = finite.next()?;
    let mut n = 1;
    for x in finite {
        if x != first {
            return None;
        }
        n += 1;
    }
    (n >= 2).then_some(first)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn exact_zeros_are_constant_and_one_change_is_not() {
        assert_eq!(value(&[0.0; 50]), Some(0.0));
        assert_eq!(value(&[f64::NAN, 2.5, 2.5, f64::NAN]), Some(2.5));
        let mut v = vec![0.0; 50];
        v[30] = 1e-9;
        assert_eq!(value(&v), None);
        assert_eq!(value(&[1.0]), None);
    }
}
