//! Work spread over threads: one shared queue of items (a thread takes the next item not yet
//! taken, so uneven items balance), the results in the items' order. The diagnosis's class fits,
//! the blind test's trials and `ddct sim`'s scenarios run through it.

/// `f(i, item)` for every item on up to `threads` threads; the results in index order. A panic
/// in `f` is raised again here, not turned into a missing result.
pub fn map<T: Sync, R: Send>(
    threads: usize,
    items: &[T],
    f: impl Fn(usize, &T) -> R + Sync,
) -> Vec<R> {
    let threads = threads.clamp(1, items.len().max(1));
    let next = std::sync::atomic::AtomicUsize::new(0);
    let mut done: Vec<(usize, R)> = std::thread::scope(|sc| {
        let handles: Vec<_> = (0..threads)
            .map(|_| {
                let (next, f) = (&next, &f);
                sc.spawn(move || {
                    let mut mine = Vec::new();
                    loop {
                        let i = next.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
                        let Some(item) = items.get(i) else { break };
                        mine.push((i, f(i, item)));
                    }
                    mine
                })
            })
            .collect();
        handles
            .into_iter()
            .flat_map(|h| h.join().unwrap_or_else(|e| std::panic::resume_unwind(e)))
            .collect()
    });
    done.sort_by_key(|(i, _)| *i);
    done.into_iter().map(|(_, r)| r).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every item once, in order, whatever the thread count and however uneven the items.
    #[test]
    fn every_item_once_in_order() {
        let items: Vec<u64> = (0..57).collect();
        for threads in [0, 1, 2, 7, 100] {
            let out = map(threads, &items, |i, &x| {
                // Uneven work: some items take much longer.
                if x % 5 == 0 {
                    std::thread::sleep(std::time::Duration::from_millis(2));
                }
                (i, x * x)
            });
            assert_eq!(out.len(), items.len());
            for (k, (i, sq)) in out.iter().enumerate() {
                assert_eq!((*i, *sq), (k, items[k] * items[k]));
            }
        }
        assert!(map(2, &[] as &[u8], |_, _| 1).is_empty());
    }
}
