-- Recordings in an object store (issue 33): the SHA-256 (hex) of an attempt's `.mcap` and
-- `.rrd` once stored there, their keys in the store. NULL: only on the station's disk
-- (`recording_path`).
ALTER TABLE attempts ADD COLUMN recording_sha256 TEXT;
ALTER TABLE attempts ADD COLUMN rrd_sha256 TEXT;
