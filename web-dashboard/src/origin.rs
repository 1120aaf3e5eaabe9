//! Where people reach this dashboard: the origin (`scheme://host[:port]`) the links it hands
//! out are built from (the replay viewer fetches its recording by an absolute address). A
//! configured [`PublicUrl`] wins; else the request's `Host` with `https` when the cookies are
//! `Secure` or a proxy in front says the request came over TLS (`X-Forwarded-Proto`), else
//! `http`.

use axum::http::{HeaderMap, header};

use crate::Config;

/// The dashboard's public origin, checked: `http://` or `https://`, then a host of letters,
/// digits, `.-:[]` and nothing after it but an optional `/`.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct PublicUrl(String);

impl PublicUrl {
    pub fn as_str(&self) -> &str {
        &self.0
    }
}

impl std::str::FromStr for PublicUrl {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        let s = s.trim().trim_end_matches('/');
        let host = s
            .strip_prefix("https://")
            .or_else(|| s.strip_prefix("http://"))
            .ok_or_else(|| format!("{s:?}: an http:// or https:// address"))?;
        if !host_ok(host) {
            return Err(format!(
                "{s:?}: a scheme and a host (letters, digits, . - : [ ]), no path"
            ));
        }
        Ok(Self(s.to_owned()))
    }
}

fn host_ok(host: &str) -> bool {
    !host.is_empty()
        && host.len() <= 255
        && host
            .bytes()
            .all(|c| c.is_ascii_alphanumeric() || b".-:[]".contains(&c))
}

/// The origin of the links handed out in answer to a request with `headers`; `None` without
/// a public URL and a usable `Host`.
pub fn request_origin(headers: &HeaderMap, config: &Config) -> Option<String> {
    if let Some(url) = &config.public_url {
        return Some(url.as_str().to_owned());
    }
    let host = headers.get(header::HOST)?.to_str().ok()?;
    let forwarded_tls = headers
        .get("x-forwarded-proto")
        .and_then(|v| v.to_str().ok())
        .is_some_and(|v| v.trim().eq_ignore_ascii_case("https"));
    let https = config.secure_cookies || forwarded_tls;
    host_ok(host).then(|| format!("{}://{host}", if https { "https" } else { "http" }))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn headers(pairs: &[(&'static str, &'static str)]) -> HeaderMap {
        let mut h = HeaderMap::new();
        for (k, v) in pairs {
            h.insert(*k, v.parse().unwrap());
        }
        h
    }

    #[test]
    fn public_urls_are_a_scheme_and_a_host() {
        let u: PublicUrl = "https://cutlab.example.org/".parse().unwrap();
        assert_eq!(u.as_str(), "https://cutlab.example.org");
        assert!("http://[::1]:8080".parse::<PublicUrl>().is_ok());
        for bad in [
            "cutlab.example.org",
            "ftp://x",
            "https://",
            "https://a/b",
            "https://a\"onload=x",
        ] {
            assert!(bad.parse::<PublicUrl>().is_err(), "{bad}");
        }
    }

    #[test]
    fn the_origin_follows_the_configuration_then_the_request() {
        let plain = Config::default();
        let h = headers(&[("host", "ward:8080")]);
        assert_eq!(request_origin(&h, &plain).unwrap(), "http://ward:8080");
        let tls = headers(&[("host", "ward"), ("x-forwarded-proto", "https")]);
        assert_eq!(request_origin(&tls, &plain).unwrap(), "https://ward");
        let secure = Config {
            secure_cookies: true,
            ..Config::default()
        };
        assert_eq!(request_origin(&h, &secure).unwrap(), "https://ward:8080");
        let public = Config {
            public_url: Some("https://cutlab.example.org".parse().unwrap()),
            ..Config::default()
        };
        assert_eq!(
            request_origin(&h, &public).unwrap(),
            "https://cutlab.example.org"
        );
        assert!(request_origin(&headers(&[("host", "a b")]), &plain).is_none());
        assert!(request_origin(&HeaderMap::new(), &plain).is_none());
    }
}
