//! Identities that cannot repeat: random ids and secrets from the kernel's
//! generator, as lowercase hex, and their comparison in constant time.
//!
//! Jobs (128-bit ids, 256-bit secrets), worker sessions (128 bits) and
//! coordinator runs (128 bits) are named this way, so that no id of one
//! coordinator run can be mistaken for another's and none can be guessed.

/// Fills `b` from the kernel's generator: one `getrandom` system call,
/// not a file opened, read and closed (ids are made per task, and the
/// coordinator's per-task profile showed the three calls).
fn fill(b: &mut [u8]) {
    getrandom::fill(b).expect("the kernel's random generator failed");
}

/// `bytes` random bytes from the kernel's generator, as hex.
pub fn random_hex(bytes: usize) -> String {
    let mut b = vec![0u8; bytes];
    fill(&mut b);
    hex(&b)
}

/// A random 64-bit number.
pub fn random_u64() -> u64 {
    let mut b = [0u8; 8];
    fill(&mut b);
    u64::from_le_bytes(b)
}

pub fn hex(b: &[u8]) -> String {
    b.iter().map(|x| format!("{x:02x}")).collect()
}

/// A job id: 32 lowercase hex digits.
pub fn new_job_id() -> String {
    random_hex(16)
}

/// A job's secret: 64 lowercase hex digits.
pub fn new_secret() -> String {
    random_hex(32)
}

/// A worker session or a coordinator run: 32 lowercase hex digits.
pub fn new_session() -> String {
    random_hex(16)
}

/// Whether `s` is `digits` lowercase hex digits (a well-formed id).
pub fn is_hex_id(s: &str, digits: usize) -> bool {
    s.len() == digits
        && s.bytes()
            .all(|b| b.is_ascii_digit() || (b'a'..=b'f').contains(&b))
}

/// Compares in time independent of where the first difference lies.
pub fn same(a: &[u8], b: &[u8]) -> bool {
    a.len() == b.len() && a.iter().zip(b).fold(0u8, |acc, (x, y)| acc | (x ^ y)) == 0
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ids_are_hex_and_do_not_repeat() {
        let a = new_job_id();
        let b = new_job_id();
        assert!(is_hex_id(&a, 32) && is_hex_id(&b, 32));
        assert_ne!(a, b);
        assert!(is_hex_id(&new_secret(), 64));
        assert!(!is_hex_id("1", 32));
        assert!(same(b"abc", b"abc") && !same(b"abc", b"abd") && !same(b"ab", b"abc"));
    }
}
