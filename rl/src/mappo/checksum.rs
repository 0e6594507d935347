//! The checksummed envelope of a checkpoint file:
//!
//! ```text
//! {"sha256":"<64 hex digits>","checkpoint":<the payload, a JSON object>}
//! ```
//!
//! The digest covers the payload's exact bytes, so any changed byte (a flipped digit, a
//! truncated file, a hand edit) is found before the payload is trusted. The file stays valid
//! JSON. Files written before the envelope existed (a bare payload) have no checksum to
//! check; [`unseal`] says so and [`crate::mappo::checkpoint::Checkpoint::load`] accepts them by their
//! format version.

use serde::{Deserialize, Serialize};
use serde_json::value::RawValue;
use sha2::{Digest, Sha256};

/// The SHA-256 digest of `bytes` in lower-case hexadecimal.
pub fn sha256_hex(bytes: &[u8]) -> String {
    Sha256::digest(bytes).iter().map(|b| format!("{b:02x}")).collect()
}

#[derive(Serialize, Deserialize)]
struct Envelope<'a> {
    sha256: String,
    #[serde(borrow)]
    checkpoint: &'a RawValue,
}

/// Wraps a JSON payload in the envelope (module docs).
pub fn seal(payload: &[u8]) -> Vec<u8> {
    let mut out = Vec::with_capacity(payload.len() + 100);
    out.extend_from_slice(b"{\"sha256\":\"");
    out.extend_from_slice(sha256_hex(payload).as_bytes());
    out.extend_from_slice(b"\",\"checkpoint\":");
    out.extend_from_slice(payload);
    out.push(b'}');
    out
}

/// What [`unseal`] found.
#[derive(Debug, PartialEq)]
pub enum Unsealed<'a> {
    /// An envelope whose digest matches: the payload.
    Checked(&'a str),
    /// No envelope (a file written before checksums): the whole file is the payload.
    Unchecked(&'a [u8]),
}

/// The payload of a file written by [`seal`], checked against its digest; a file that is
/// not an envelope is returned whole as [`Unsealed::Unchecked`]. Errors say what is wrong.
pub fn unseal(bytes: &[u8]) -> Result<Unsealed<'_>, String> {
    if !looks_sealed(bytes) {
        return Ok(Unsealed::Unchecked(bytes));
    }
    let e: Envelope = serde_json::from_slice(bytes).map_err(|e| format!("not a valid checkpoint: {e}"))?;
    let payload = e.checkpoint.get();
    let actual = sha256_hex(payload.as_bytes());
    if actual != e.sha256 {
        return Err(format!(
            "checksum mismatch: the file was changed or damaged after it was written (SHA-256 recorded {}, \
             computed {actual})",
            e.sha256
        ));
    }
    Ok(Unsealed::Checked(payload))
}

/// Whether the file's first key is `sha256` (the envelope), whitespace allowed.
fn looks_sealed(bytes: &[u8]) -> bool {
    let mut rest = bytes.iter().skip_while(|b| b.is_ascii_whitespace());
    if rest.next() != Some(&b'{') {
        return false;
    }
    let rest: Vec<u8> = rest.skip_while(|b| b.is_ascii_whitespace()).take(8).copied().collect();
    rest == b"\"sha256\""
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sealed_payloads_come_back_and_any_changed_byte_is_found() {
        let payload = br#"{"version":2,"iteration":12,"x":[1.5,-3e-7]}"#;
        let sealed = seal(payload);
        serde_json::from_slice::<serde_json::Value>(&sealed).expect("the envelope is JSON");
        assert_eq!(unseal(&sealed).unwrap(), Unsealed::Checked(std::str::from_utf8(payload).unwrap()));
        let text = String::from_utf8(sealed).unwrap();
        let e = unseal(text.replace("12", "13").as_bytes()).unwrap_err();
        assert!(e.contains("checksum mismatch"), "{e}");
        assert!(unseal(&text.as_bytes()[..text.len() - 5]).unwrap_err().contains("not a valid checkpoint"));
        assert_eq!(unseal(payload).unwrap(), Unsealed::Unchecked(payload));
        assert_eq!(sha256_hex(b"abc"), "ba7816bf8f01cfea414140de5dae2223b00361a396177a9cb410ff61f20015ad");
    }
}
