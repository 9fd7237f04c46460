//! A bounded hand-off that drops the oldest item instead of blocking the producer, so that a
//! slow consumer (a stalled subscriber, a slow link) never holds back capture.

use std::collections::VecDeque;
use std::sync::{Condvar, Mutex};
use std::time::Duration;

/// Multi-producer, single-consumer, at most `capacity` items waiting.
pub struct DropOldest<T> {
    state: Mutex<State<T>>,
    ready: Condvar,
    capacity: usize,
}

struct State<T> {
    items: VecDeque<T>,
    dropped: u64,
    closed: bool,
}

impl<T> DropOldest<T> {
    pub fn new(capacity: usize) -> Self {
        DropOldest {
            state: Mutex::new(State { items: VecDeque::new(), dropped: 0, closed: false }),
            ready: Condvar::new(),
            capacity: capacity.max(1),
        }
    }

    /// Queues `item`; if the queue is full the oldest waiting item is dropped (and counted).
    pub fn push(&self, item: T) {
        let mut s = self.state.lock().unwrap_or_else(|e| e.into_inner());
        if s.items.len() >= self.capacity {
            s.items.pop_front();
            s.dropped += 1;
        }
        s.items.push_back(item);
        self.ready.notify_one();
    }

    /// No more items will come: the consumer drains what waits, then gets `None`.
    pub fn close(&self) {
        self.state.lock().unwrap_or_else(|e| e.into_inner()).closed = true;
        self.ready.notify_all();
    }

    /// The oldest waiting item; blocks until one comes, `None` once closed and drained.
    pub fn pop(&self) -> Option<T> {
        let mut s = self.state.lock().unwrap_or_else(|e| e.into_inner());
        loop {
            if let Some(item) = s.items.pop_front() {
                return Some(item);
            }
            if s.closed {
                return None;
            }
            s = self.ready.wait_timeout(s, Duration::from_millis(200)).unwrap_or_else(|e| e.into_inner()).0;
        }
    }

    /// Items dropped so far.
    pub fn dropped(&self) -> u64 {
        self.state.lock().unwrap_or_else(|e| e.into_inner()).dropped
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_full_queue_drops_its_oldest_item_and_counts_it() {
        let q = DropOldest::new(2);
        (1..=5).for_each(|i| q.push(i));
        q.close();
        assert_eq!((q.pop(), q.pop(), q.pop()), (Some(4), Some(5), None));
        assert_eq!(q.dropped(), 3);
    }

    #[test]
    fn the_consumer_waits_for_an_item_from_another_thread() {
        let q = std::sync::Arc::new(DropOldest::new(4));
        let q2 = q.clone();
        let producer = std::thread::spawn(move || {
            std::thread::sleep(Duration::from_millis(30));
            q2.push(7);
            q2.close();
        });
        assert_eq!(q.pop(), Some(7));
        assert_eq!(q.pop(), None);
        producer.join().unwrap();
    }
}
