-- A hostile station (issue 46). On a hub: which station uploaded which recording (by its
-- key). A station may attach to its attempts only the recordings it uploaded itself, so it
-- cannot attach another station's trainee's recording it only knows the key of (having the
-- bytes, it could upload them: that is no leak).
CREATE TABLE recording_owners (
    sha256 TEXT NOT NULL,
    station TEXT NOT NULL,
    uploaded_ns BIGINT NOT NULL,
    PRIMARY KEY (sha256, station)
);
