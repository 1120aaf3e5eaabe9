-- The dashboard's tables (issue 7): login sessions, debriefing comments and sign-offs.
-- Portable SQL like the assessor's migration; times are integer nanoseconds since the epoch.

-- A logged-in browser. The cookie carries a random token; only its SHA-256 (hex) is kept, so
-- a copy of the database does not log anyone in. `csrf_token` is the per-session token every
-- form carries back.
CREATE TABLE login_sessions (
    token_sha256 TEXT PRIMARY KEY,
    user_id BIGINT NOT NULL REFERENCES users (id) ON DELETE CASCADE,
    csrf_token TEXT NOT NULL,
    created_ns BIGINT NOT NULL,
    expires_ns BIGINT NOT NULL
);
CREATE INDEX login_sessions_by_expiry ON login_sessions (expires_ns);

-- An instructor's (or administrator's) comment on an attempt; the trainee reads them.
CREATE TABLE attempt_comments (
    id INTEGER PRIMARY KEY,
    attempt_id BIGINT NOT NULL REFERENCES attempts (id) ON DELETE CASCADE,
    author_id BIGINT NOT NULL REFERENCES users (id),
    body TEXT NOT NULL,
    created_ns BIGINT NOT NULL
);
CREATE INDEX attempt_comments_by_attempt ON attempt_comments (attempt_id, created_ns);

-- The debriefing is done: an instructor signed the attempt off.
CREATE TABLE attempt_signoffs (
    attempt_id BIGINT PRIMARY KEY REFERENCES attempts (id) ON DELETE CASCADE,
    instructor_id BIGINT NOT NULL REFERENCES users (id),
    signed_ns BIGINT NOT NULL
);

-- Who may see whom: the cohorts a user is in.
CREATE INDEX cohort_members_by_user ON cohort_members (user_id);
-- The supervision page: running attempts.
CREATE INDEX attempts_by_status ON attempts (status, started_ns);
