//! Body encryption compatible with libdccl: AES-256 in counter mode (128-bit
//! big-endian counter), key = SHA-256 of the passphrase, initial counter =
//! the first 16 bytes of SHA-256 of the encoded header. The header stays clear.

use aes::Aes256;
use ctr::cipher::{KeyIvInit, StreamCipher};
use sha2::{Digest, Sha256};

type Aes256Ctr = ctr::Ctr128BE<Aes256>;

/// A key derived from a passphrase.
#[derive(Clone)]
pub struct CryptoKey([u8; 32]);

impl std::fmt::Debug for CryptoKey {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("CryptoKey(..)")
    }
}

impl CryptoKey {
    /// SHA-256 of the passphrase.
    pub fn from_passphrase(passphrase: &str) -> Self {
        CryptoKey(Sha256::digest(passphrase.as_bytes()).into())
    }

    /// Encrypts or decrypts (the same operation in counter mode) `body` in place.
    pub fn apply(&self, head: &[u8], body: &mut [u8]) {
        let digest = Sha256::digest(head);
        let mut iv = [0u8; 16];
        iv.copy_from_slice(&digest[..16]);
        let mut cipher = Aes256Ctr::new(&self.0.into(), &iv.into());
        cipher.apply_keystream(body);
    }
}
