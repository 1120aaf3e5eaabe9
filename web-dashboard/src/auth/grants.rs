//! Replay grants: a URL that lets rerun's web viewer fetch one attempt's `.rrd` without the
//! session cookie (the viewer's own HTTP client does not send cookies). A grant names the
//! attempt, the user it was issued to, the login session it was issued in (the first
//! [`SESSION_REF_CHARS`] of its token's hash) and an expiry, signed with HMAC-SHA-256 under a
//! key that lives only in this process's memory; it is issued only to a user who may see the
//! attempt, lasts [`GRANT_TTL_S`], and ends with its session (logout: the caller checks
//! [`Grant::session_ref`] against the live sessions).

use hmac::{Hmac, Mac};
use sha2::Sha256;

use super::tokens::{hex, same_token};
use crate::error::AppError;

/// How long a grant lasts.
pub const GRANT_TTL_S: u64 = 3600;

/// The characters of a session token's hash a grant carries.
pub const SESSION_REF_CHARS: usize = 32;

/// What a live grant names.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Grant {
    pub user_id: i64,
    /// The start of the hash of the session's token.
    pub session_ref: String,
}

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

    fn mac(&self, attempt_id: i64, user_id: i64, expires_s: u64, session_ref: &str) -> String {
        let mut m = <Hmac<Sha256> as Mac>::new_from_slice(&self.0)
            .unwrap_or_else(|_| unreachable!("HMAC takes any key length"));
        m.update(format!("rrd:{attempt_id}:{user_id}:{expires_s}:{session_ref}").as_bytes());
        hex(&m.finalize().into_bytes())
    }

    /// A grant for `user_id`, logged in with the session whose token hashes to
    /// `session_hash`, to fetch attempt `attempt_id`'s `.rrd`: `USER-EXPIRES-SESSION-MAC`.
    pub fn issue(&self, attempt_id: i64, user_id: i64, session_hash: &str) -> String {
        let expires = now_s() + GRANT_TTL_S;
        let session_ref: String = session_hash
            .chars()
            .take(SESSION_REF_CHARS)
            .filter(char::is_ascii_hexdigit)
            .collect();
        let mac = self.mac(attempt_id, user_id, expires, &session_ref);
        format!("{user_id}-{expires}-{session_ref}-{mac}")
    }

    /// What `grant` names if it is an unexpired grant of this key for attempt `attempt_id`.
    pub fn check(&self, attempt_id: i64, grant: &str) -> Option<Grant> {
        let mut parts = grant.splitn(4, '-');
        let (user, expires, session_ref, mac) =
            (parts.next()?, parts.next()?, parts.next()?, parts.next()?);
        let (user_id, expires) = (user.parse::<i64>().ok()?, expires.parse::<u64>().ok()?);
        let live = expires >= now_s()
            && same_token(mac, &self.mac(attempt_id, user_id, expires, session_ref));
        live.then(|| Grant {
            user_id,
            session_ref: session_ref.to_owned(),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn grants_are_for_one_attempt_and_unforgeable() {
        let k = GrantKey::random().unwrap();
        let session = "ab".repeat(32);
        let g = k.issue(7, 3, &session);
        let named = k.check(7, &g).unwrap();
        assert_eq!(named.user_id, 3);
        assert_eq!(named.session_ref, session[..SESSION_REF_CHARS]);
        assert!(k.check(8, &g).is_none(), "another attempt");
        assert!(
            GrantKey::random().unwrap().check(7, &g).is_none(),
            "another key"
        );
        let (user, rest) = g.split_once('-').unwrap();
        assert_eq!(user, "3");
        assert!(k.check(7, &format!("4-{rest}")).is_none(), "another user");
        let other = g.replace(&session[..SESSION_REF_CHARS], &"cd".repeat(16));
        assert!(k.check(7, &other).is_none(), "another session");
        let expired = format!(
            "3-1-{}-{}",
            named.session_ref,
            k.mac(7, 3, 1, &named.session_ref)
        );
        assert!(k.check(7, &expired).is_none());
        for bad in ["", "1-2", "a-b-c", "1-2-3", "1-2-3-4-5"] {
            assert!(k.check(7, bad).is_none(), "{bad}");
        }
    }
}
