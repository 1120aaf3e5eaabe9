-- Stations and hub (issue 33). On every database: an attempt's global id (a UUID made
-- where it was recorded; an attempt uploaded twice is still one attempt), and on a station,
-- when it reached the hub (NULL: still queued) and why the last upload failed.
ALTER TABLE attempts ADD COLUMN uuid TEXT;
ALTER TABLE attempts ADD COLUMN synced_ns BIGINT;
ALTER TABLE attempts ADD COLUMN sync_error TEXT;
-- On a hub: the station that uploaded the attempt (its token's name); NULL: recorded here.
ALTER TABLE attempts ADD COLUMN station TEXT;
CREATE UNIQUE INDEX attempts_uuid ON attempts (uuid);

-- On a hub: the stations that may upload attempts, each with a token of its own (only its
-- SHA-256 is kept) that may create attempts and nothing else; revoked, not deleted.
CREATE TABLE station_tokens (
    id INTEGER PRIMARY KEY,
    name TEXT NOT NULL UNIQUE,
    token_hash TEXT NOT NULL UNIQUE,
    created_ns BIGINT NOT NULL,
    revoked_ns BIGINT,
    last_used_ns BIGINT
);
