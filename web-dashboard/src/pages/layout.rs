//! The frame of every page (navigation, log-out form with its CSRF token), the login form
//! and error pages. maud escapes every interpolated string.

use axum::body::Bytes;
use axum::http::StatusCode;
use axum::response::Html;
use cutlab_assessor::store::iso8601;
use maud::{DOCTYPE, Markup, PreEscaped, html};

use crate::auth::CurrentUser;

/// [`page`] around a body rendered before (a cached one): one copy of it, not a render.
pub fn page_around(title: &str, user: Option<&CurrentUser>, body: &[u8]) -> Html<Bytes> {
    const SLOT: &str = "\u{1}body\u{1}";
    let shell = page(title, user, PreEscaped(SLOT.to_owned())).into_string();
    // the last one: the title and the user's name (user text) come before the body
    let (head, tail) = shell.rsplit_once(SLOT).unwrap_or((shell.as_str(), ""));
    let mut out = Vec::with_capacity(head.len() + body.len() + tail.len());
    out.extend_from_slice(head.as_bytes());
    out.extend_from_slice(body);
    out.extend_from_slice(tail.as_bytes());
    Html(Bytes::from(out))
}

/// A page: `title`, the navigation for `user` (if logged in), `body`.
pub fn page(title: &str, user: Option<&CurrentUser>, body: Markup) -> Markup {
    html! {
        (DOCTYPE)
        html lang="en" {
            head {
                meta charset="utf-8";
                meta name="viewport" content="width=device-width, initial-scale=1";
                title { (title) " · cutlab" }
                link rel="stylesheet" href="/static/style.css";
            }
            body {
                header {
                    a class="brand" href="/" { "cutlab" }
                    @if let Some(u) = user {
                        nav {
                            @if u.is_staff() {
                                a href="/cohorts" { "Cohorts" }
                                a href="/supervision" { "Supervision" }
                                a href="/curriculum" { "Curriculum" }
                            } @else {
                                a href=(format!("/trainees/{}", u.id())) { "My progress" }
                                a href="/supervision" { "Running" }
                                a href="/curriculum" { "Curriculum" }
                            }
                        }
                        form class="logout" method="post" action="/logout" {
                            span class="who" { (u.user().name) " (" (u.role()) ")" }
                            input type="hidden" name="csrf" value=(u.csrf());
                            button type="submit" { "Log out" }
                        }
                    }
                }
                main {
                    h1 { (title) }
                    (body)
                }
            }
        }
    }
}

/// The login form; `csrf` is the double-submit token also set as a cookie.
pub fn login_page(csrf: &str, message: Option<&str>) -> Markup {
    page(
        "Log in",
        None,
        html! {
            @if let Some(m) = message { p class="fail" { (m) } }
            form class="login" method="post" action="/login" {
                input type="hidden" name="csrf" value=(csrf);
                label { "User name " input type="text" name="username" autocomplete="username" required maxlength="256" autofocus; }
                label { "Password " input type="password" name="password" autocomplete="current-password" required maxlength="256"; }
                button type="submit" { "Log in" }
            }
        },
    )
}

/// An error page.
pub fn error_page(status: StatusCode, message: &str) -> Markup {
    page(
        status.canonical_reason().unwrap_or("Error"),
        None,
        html! {
            p { (message) }
            p { a href="/" { "Back to the dashboard" } }
        },
    )
}

/// A time for people: ISO 8601 UTC to the second.
pub fn when(ns: i64) -> String {
    let s = iso8601(ns);
    format!("{} {}", &s[..10], &s[11..19])
}

/// A number with `digits` decimals, or a dash.
pub fn num(v: Option<f64>, digits: usize) -> String {
    match v {
        Some(v) if v.is_finite() => format!("{v:.digits$}"),
        _ => "–".into(),
    }
}

/// Pass limits (SI values times `f`, the display factor) with 3 decimals: "a … b", "≥ a",
/// "≤ b", or a dash without any.
pub fn limits(lower: Option<f64>, upper: Option<f64>, f: f64) -> String {
    match (lower, upper) {
        (Some(l), Some(u)) => format!("{} … {}", num(Some(l * f), 3), num(Some(u * f), 3)),
        (Some(l), None) => format!("≥ {}", num(Some(l * f), 3)),
        (None, Some(u)) => format!("≤ {}", num(Some(u * f), 3)),
        (None, None) => "–".into(),
    }
}

/// A pass / fail mark.
pub fn verdict(passed: Option<bool>) -> Markup {
    match passed {
        Some(true) => html! { span class="pass" { "pass" } },
        Some(false) => html! { span class="fail" { "fail" } },
        None => html! { span class="muted" { "–" } },
    }
}
