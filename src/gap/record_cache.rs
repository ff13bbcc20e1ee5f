//! A record's cache of model-free per-sample series ([`super::windows`], [`super::slip_shapes`]):
//! made on first use, kept for every model a diagnosis evaluates on the record, shared by the
//! record's clones. An entry states what it was made from; a lookup that matches none makes a new
//! entry. The cache only saves work: an entry holds what its maker computes.

use std::sync::{Arc, Mutex};

/// Entries of type `T` of one record.
#[derive(Debug)]
pub struct RecordCache<T>(Arc<Mutex<Vec<Arc<T>>>>);

impl<T> Default for RecordCache<T> {
    fn default() -> Self {
        RecordCache(Arc::default())
    }
}

impl<T> Clone for RecordCache<T> {
    fn clone(&self) -> Self {
        RecordCache(self.0.clone())
    }
}

impl<T> RecordCache<T> {
    /// The entry for which `is` holds, or the one `make` makes (and keeps).
    pub fn get(&self, is: impl Fn(&T) -> bool, make: impl FnOnce() -> T) -> Arc<T> {
        let mut kept = self.0.lock().unwrap_or_else(|e| e.into_inner());
        if let Some(e) = kept.iter().find(|e| is(e)) {
            return e.clone();
        }
        let e = Arc::new(make());
        kept.push(e.clone());
        e
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
        let c: RecordCache<(u32, u64)> = RecordCache::default();
        let made = std::cell::Cell::new(0);
        let get = |c: &RecordCache<(u32, u64)>, k: u32| {
            c.get(
                |e| e.0 == k,
                || {
                    made.set(made.get() + 1);
                    (k, u64::from(k) * 10)
                },
            )
        };
        let a = get(&c, 1);
        assert!(Arc::ptr_eq(&a, &get(&c.clone(), 1)));
        assert_eq!(get(&c, 2).1, 20);
        assert_eq!(made.get(), 2);
    }
}
