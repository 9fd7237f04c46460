//! A deterministic mutation engine: the same seed gives the same inputs, so any run replays.
//!
//! Each mutation stacks one to four edits on a base input: bit flips, random or interesting
//! bytes, inserts, deletes, duplicated ranges, splices with a second input, and numbers and
//! tokens the readers must handle (0, -1, 1e308, NaN, huge integers, `null`, …), written over a
//! number already in the input or inserted anywhere. Inputs never exceed the length limit.

use omni_geom::rng::SplitMix64;

/// Tokens that stress text parsers: limits of the integer types, non-finite and huge floats,
/// JSON values of the wrong kind, protocol separators.
const TOKENS: &[&str] = &[
    "0",
    "-1",
    "1",
    "-0",
    "2",
    "255",
    "256",
    "65535",
    "65536",
    "2147483647",
    "-2147483648",
    "4294967295",
    "4294967296",
    "9223372036854775807",
    "18446744073709551615",
    "18446744073709551616",
    "99999999999999999999999999",
    "1e308",
    "-1e308",
    "1e309",
    "1e-320",
    "1e40",
    "0.5",
    "NaN",
    "nan",
    "inf",
    "-inf",
    "Infinity",
    "null",
    "true",
    "\"\"",
    "[]",
    "{}",
    "[[]]",
    "\"x\"",
    ",",
    ":",
    "\n",
    "\r\n",
    " ",
    "*",
    "=",
    "NONE",
    "ALL",
    "\u{e9}",
    "\u{0}",
];

/// Bytes that often matter: delimiters and the edges of the byte range.
const BYTES: &[u8] = b"\x00\x01\x7f\x80\xff\n\r\t \"\\,:[]{}*=-+.eE0";

/// Mutates inputs with its own RNG stream.
pub struct Mutator {
    rng: SplitMix64,
    max_len: usize,
}

impl Mutator {
    /// A mutator whose inputs are at most `max_len` bytes, its sequence fixed by `seed`.
    pub fn new(seed: u64, max_len: usize) -> Self {
        Mutator { rng: SplitMix64::new(seed), max_len }
    }

    /// The RNG, for choosing seeds with the same stream.
    pub fn below(&mut self, n: usize) -> usize {
        self.rng.below(n.max(1))
    }

    /// Writes a mutation of `base` into `out` (its old contents are dropped); `other` is the
    /// second input of splices.
    pub fn mutate(&mut self, base: &[u8], other: &[u8], out: &mut Vec<u8>) {
        out.clear();
        out.extend_from_slice(&base[..base.len().min(self.max_len)]);
        let edits = 1 + self.rng.below(4);
        for _ in 0..edits {
            self.edit(other, out);
            out.truncate(self.max_len);
        }
    }

    fn edit(&mut self, other: &[u8], out: &mut Vec<u8>) {
        match self.rng.below(10) {
            0 => self.flip_bit(out),
            1 => self.set_byte(out),
            2 => self.insert_bytes(out),
            3 => self.delete_range(out),
            4 => self.duplicate_range(out),
            5 => self.splice(other, out),
            6 | 7 => self.replace_number(out),
            _ => self.insert_token(out),
        }
    }

    fn pos(&mut self, out: &[u8]) -> usize {
        self.rng.below(out.len() + 1)
    }

    fn flip_bit(&mut self, out: &mut [u8]) {
        if !out.is_empty() {
            let i = self.rng.below(out.len());
            out[i] ^= 1 << self.rng.below(8);
        }
    }

    fn set_byte(&mut self, out: &mut [u8]) {
        if !out.is_empty() {
            let i = self.rng.below(out.len());
            out[i] = self.byte();
        }
    }

    fn byte(&mut self) -> u8 {
        if self.rng.chance(0.5) { BYTES[self.rng.below(BYTES.len())] } else { self.rng.next_u64() as u8 }
    }

    fn insert_bytes(&mut self, out: &mut Vec<u8>) {
        let at = self.pos(out);
        let n = 1 + self.rng.below(8);
        let bytes: Vec<u8> = (0..n).map(|_| self.byte()).collect();
        out.splice(at..at, bytes);
    }

    fn range(&mut self, out: &[u8]) -> (usize, usize) {
        let start = self.pos(out);
        let max = (out.len() - start).min(if self.rng.chance(0.8) { 16 } else { 4096 });
        (start, start + self.rng.below(max + 1))
    }

    fn delete_range(&mut self, out: &mut Vec<u8>) {
        let (a, b) = self.range(out);
        out.drain(a..b);
    }

    fn duplicate_range(&mut self, out: &mut Vec<u8>) {
        let (a, b) = self.range(out);
        let copy = out[a..b].to_vec();
        let at = self.pos(out);
        out.splice(at..at, copy);
    }

    /// Keeps a prefix of the input and continues with a part of `other`.
    fn splice(&mut self, other: &[u8], out: &mut Vec<u8>) {
        let cut = self.pos(out);
        let from = self.rng.below(other.len() + 1);
        out.truncate(cut);
        out.extend_from_slice(&other[from..]);
    }

    fn insert_token(&mut self, out: &mut Vec<u8>) {
        let at = self.pos(out);
        let token = TOKENS[self.rng.below(TOKENS.len())].as_bytes();
        out.splice(at..at, token.iter().copied());
    }

    /// Writes a token over a number (a run of digits, with its sign, dot and exponent) found
    /// from a random place on; inserts it if there is none.
    fn replace_number(&mut self, out: &mut Vec<u8>) {
        let from = self.pos(out);
        let Some(start) = out[from..].iter().position(u8::is_ascii_digit).map(|i| i + from) else {
            return self.insert_token(out);
        };
        let start = if start > 0 && out[start - 1] == b'-' { start - 1 } else { start };
        let len = out[start..].iter().skip(1).take_while(|b| b.is_ascii_digit() || b".eE+-".contains(b)).count() + 1;
        let token = TOKENS[self.rng.below(TOKENS.len())].as_bytes();
        out.splice(start..start + len, token.iter().copied());
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_same_seed_gives_the_same_inputs_within_the_limit() {
        let (mut a, mut b) = (Mutator::new(7, 64), Mutator::new(7, 64));
        let (mut x, mut y) = (Vec::new(), Vec::new());
        for _ in 0..1000 {
            a.mutate(b"{\"n\": 12, \"f\": -3.5e2}", b"other 99", &mut x);
            b.mutate(b"{\"n\": 12, \"f\": -3.5e2}", b"other 99", &mut y);
            assert_eq!(x, y);
            assert!(x.len() <= 64);
        }
    }

    #[test]
    fn numbers_are_replaced_by_interesting_tokens() {
        let mut m = Mutator::new(1, 1 << 10);
        let seen = (0..2000).any(|_| {
            let mut out = b"{\"n\": 12}".to_vec();
            m.replace_number(&mut out);
            out.windows(5).any(|w| w == b"1e308")
        });
        assert!(seen);
    }
}
