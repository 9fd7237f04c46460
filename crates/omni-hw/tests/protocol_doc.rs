//! docs/PROTOCOL.md is the spec firmware authors follow: every example line in it must verify
//! and parse with this implementation.

use omni_hw::framing::decode_line;
use omni_hw::message::{DeviceMessage, Request};

#[test]
fn every_example_line_in_the_protocol_spec_verifies_and_parses() {
    let path = concat!(env!("CARGO_MANIFEST_DIR"), "/../../docs/PROTOCOL.md");
    let text = std::fs::read_to_string(path).unwrap();
    let mut checked = 0;
    for line in text.lines() {
        let (direction, framed) = match line.split_at_checked(2) {
            Some(("> ", rest)) => ('>', rest),
            Some(("< ", rest)) => ('<', rest),
            _ if line.contains('*') && line.len() > 5 && line.as_bytes()[line.len() - 5] == b'*' => ('?', line),
            _ => continue,
        };
        let framed = framed.split("  ").next().unwrap_or(framed).trim_end();
        let body = decode_line(framed.as_bytes()).unwrap_or_else(|e| panic!("{framed:?}: {e}"));
        match direction {
            '>' => assert!(Request::parse(body).is_ok(), "{body}"),
            '<' => assert!(DeviceMessage::parse(body).is_ok(), "{body}"),
            _ => assert!(Request::parse(body).is_ok() || DeviceMessage::parse(body).is_ok() || body == "123456789"),
        }
        checked += 1;
    }
    assert!(checked >= 18, "only {checked} example lines found");
}
