//! A value-keyed memo: what a pure function of a record's series made for a key (a stride, a
//! geometry's or knots' bits), kept so that the many model evaluations of a diagnosis share it.
//! Made on first use, shared by the clones of the memo (a record's clones whose series it was
//! made from are the same); never keyed by an address: two records with equal contents give equal
//! entries, whichever is asked first. It only saves work: an entry holds what its maker computes.

use std::sync::{Arc, Mutex};

/// Entries of type `V` by key `K`.
#[derive(Debug)]
pub struct Memo<K, V>(Arc<Mutex<Entries<K, V>>>);

/// What a [`Memo`] keeps: each key with its entry.
type Entries<K, V> = Vec<(K, Arc<V>)>;

impl<K, V> Default for Memo<K, V> {
    fn default() -> Self {
        Memo(Arc::default())
    }
}

impl<K, V> Clone for Memo<K, V> {
    fn clone(&self) -> Self {
        Memo(self.0.clone())
    }
}

impl<K: PartialEq, V> Memo<K, V> {
    /// The entry of `key`, or the one `make` makes (and keeps).
    pub fn get(&self, key: K, make: impl FnOnce() -> V) -> Arc<V> {
        let mut kept = self.0.lock().unwrap_or_else(|e| e.into_inner());
        if let Some((_, v)) = kept.iter().find(|(k, _)| *k == key) {
            return v.clone();
        }
        let v = Arc::new(make());
        kept.push((key, v.clone()));
        v
    }

    /// The entries kept.
    pub fn len(&self) -> usize {
        self.0.lock().unwrap_or_else(|e| e.into_inner()).len()
    }

    /// Whether none is kept.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_entry_is_made_once_per_key_and_shared_by_clones() {
        let c: Memo<u32, u64> = Memo::default();
        let made = std::cell::Cell::new(0);
        let get = |c: &Memo<u32, u64>, k: u32| {
            *c.get(k, || {
                made.set(made.get() + 1);
                u64::from(k) * 10
            })
        };
        assert_eq!(get(&c, 1), 10);
        assert_eq!(get(&c.clone(), 1), 10);
        assert_eq!(get(&c, 2), 20);
        assert_eq!(made.get(), 2);
        assert_eq!(c.len(), 2);
    }
}
