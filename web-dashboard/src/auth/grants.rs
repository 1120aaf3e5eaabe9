//! Replay grants: a URL that lets rerun's web viewer fetch one attempt's `.rrd` without the
//! session cookie (the viewer's own HTTP client does not send cookies). A grant names the
//! attempt, the user it was issued to and an expiry, signed with HMAC-SHA-256 under a key
//! that lives only in this process's memory; it is issued only to a user who may see the
//! attempt, and lasts [`GRANT_TTL_S`].

use hmac::{Hmac, Mac};
use sha2::Sha256;

use super::tokens::{hex, same_token};
use crate::error::AppError;

/// How long a grant lasts.
pub const GRANT_TTL_S: u64 = 3600;

/// The process's signing key.
#[derive(Clone)]
pub struct GrantKey([u8; 32]);

impl std::fmt::Debug for GrantKey {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("GrantKey(..)")
    }
}

fn now_s() -> u64 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.as_secs())
}

impl GrantKey {
    pub fn random() -> Result<Self, AppError> {
        let mut k = [0u8; 32];
        getrandom::fill(&mut k).map_err(|e| AppError::Internal(format!("no randomness: {e}")))?;
        Ok(Self(k))
    }

    fn mac(&self, attempt_id: i64, user_id: i64, expires_s: u64) -> String {
        let mut m = <Hmac<Sha256> as Mac>::new_from_slice(&self.0)
            .unwrap_or_else(|_| unreachable!("HMAC takes any key length"));
        m.update(format!("rrd:{attempt_id}:{user_id}:{expires_s}").as_bytes());
        hex(&m.finalize().into_bytes())
    }

    /// A grant for `user_id` to fetch attempt `attempt_id`'s `.rrd`: `USER-EXPIRES-MAC`.
    pub fn issue(&self, attempt_id: i64, user_id: i64) -> String {
        let expires = now_s() + GRANT_TTL_S;
        format!(
            "{user_id}-{expires}-{}",
            self.mac(attempt_id, user_id, expires)
        )
    }

    /// Whether `grant` is a live grant for attempt `attempt_id`.
    pub fn check(&self, attempt_id: i64, grant: &str) -> bool {
        let mut parts = grant.splitn(3, '-');
        let (Some(user), Some(expires), Some(mac)) = (parts.next(), parts.next(), parts.next())
        else {
            return false;
        };
        let (Ok(user), Ok(expires)) = (user.parse::<i64>(), expires.parse::<u64>()) else {
            return false;
        };
        expires >= now_s() && same_token(mac, &self.mac(attempt_id, user, expires))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn grants_are_for_one_attempt_and_unforgeable() {
        let k = GrantKey::random().unwrap();
        let g = k.issue(7, 3);
        assert!(k.check(7, &g));
        assert!(!k.check(8, &g), "another attempt");
        assert!(!GrantKey::random().unwrap().check(7, &g), "another key");
        let (user, rest) = g.split_once('-').unwrap();
        assert_eq!(user, "3");
        assert!(!k.check(7, &format!("4-{rest}")), "another user");
        let expired = format!("3-1-{}", k.mac(7, 3, 1));
        assert!(!k.check(7, &expired));
        assert!(!k.check(7, "") && !k.check(7, "1-2") && !k.check(7, "a-b-c"));
    }
}
