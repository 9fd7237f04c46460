//! Property tests: whatever garbage arrives between valid lines, the reader never yields a
//! wrong message, never panics, and resynchronises at the next newline.

use omni_hw::framing::{LineReader, decode_line, encode_line};
use omni_hw::message::{DeviceMessage, Request, TriggerEvent};
use proptest::prelude::*;

#[derive(Debug, Clone)]
enum Item {
    Valid(DeviceMessage),
    Garbage(Vec<u8>),
}

fn trigger() -> impl Strategy<Value = DeviceMessage> {
    (any::<u32>(), 0u32..36000, 0u32..12, 0u64..1000, any::<u64>(), proptest::collection::vec(0u32..4, 0..3)).prop_map(
        |(seq, encoder, facet, revolution, t_us, lasers)| {
            DeviceMessage::Trigger(TriggerEvent { seq: seq as u64, encoder, facet, revolution, t_us, lasers })
        },
    )
}

fn item() -> impl Strategy<Value = Item> {
    prop_oneof![
        3 => trigger().prop_map(Item::Valid),
        1 => (any::<u32>(), any::<u64>()).prop_map(|(fired, t_us)| Item::Valid(DeviceMessage::Done { fired: fired as u64, t_us })),
        // Binary noise, printable noise, and noise that looks like protocol text.
        2 => proptest::collection::vec(any::<u8>(), 1..200).prop_map(Item::Garbage),
        1 => "[ -~]{1,60}\n?".prop_map(|s| Item::Garbage(s.into_bytes())),
        1 => "(TRG|ACK|DONE|\\*|=| |[0-9A-F]){1,40}\n?".prop_map(|s| Item::Garbage(s.into_bytes())),
    ]
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 300, ..ProptestConfig::default() })]

    #[test]
    fn garbage_never_yields_a_wrong_message(items in proptest::collection::vec(item(), 1..40), chunk in 1usize..64) {
        let mut stream = Vec::new();
        let mut sent = Vec::new();
        // Valid lines that start right after a newline must come through.
        let mut must_arrive = Vec::new();
        for it in &items {
            match it {
                Item::Valid(m) => {
                    if stream.last().is_none_or(|&b| b == b'\n') {
                        must_arrive.push(m.clone());
                    }
                    stream.extend_from_slice(encode_line(&m.to_body()).as_bytes());
                    sent.push(m.clone());
                }
                Item::Garbage(g) => stream.extend_from_slice(g),
            }
        }
        let mut reader = LineReader::new();
        let mut bodies = Vec::new();
        for c in stream.chunks(chunk) {
            reader.push(c, &mut bodies);
        }
        reader.push(b"\n", &mut bodies);
        let received: Vec<DeviceMessage> = bodies.iter().filter_map(|b| DeviceMessage::parse(b).ok()).collect();
        // Received messages are a subsequence of the sent ones: nothing invented or altered.
        let mut it = sent.iter();
        for r in &received {
            prop_assert!(it.any(|s| s == r), "received {:?} which was not sent (in this order)", r);
        }
        for m in &must_arrive {
            prop_assert!(received.contains(m), "lost a clean line {:?}", m);
        }
    }

    #[test]
    fn arbitrary_bytes_never_panic_the_decoders(bytes in proptest::collection::vec(any::<u8>(), 0..300)) {
        let _ = decode_line(&bytes);
        let text = String::from_utf8_lossy(&bytes);
        let _ = Request::parse(&text);
        let _ = DeviceMessage::parse(&text);
    }
}
