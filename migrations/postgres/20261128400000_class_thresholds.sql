-- A fair score for a person (issue 41): thresholds kept per device class. A person's time,
-- path and movements with the station's pointer (a mouse or a pen: `pointer`) are not those
-- of a hand on a stylus or a tracker (`stylus`: every other device), so the thresholds
-- derived from an exercise's expert attempts are also kept per class of the experts' device.
-- An attempt is judged by its class's rows where they exist, metric by metric, and by
-- `metric_thresholds` (pooled over all experts, or set by hand) otherwise. Setting the
-- thresholds by hand removes the class rows.
CREATE TABLE class_thresholds (
    exercise_id BIGINT NOT NULL REFERENCES exercises (id) ON DELETE CASCADE,
    device_class TEXT NOT NULL CHECK (device_class IN ('pointer', 'stylus')),
    metric TEXT NOT NULL,
    better TEXT NOT NULL CHECK (better IN ('lower-is-better', 'higher-is-better', 'two-sided')),
    mean DOUBLE PRECISION NOT NULL,
    sd DOUBLE PRECISION NOT NULL,
    n_experts BIGINT NOT NULL,
    lower_limit DOUBLE PRECISION,
    upper_limit DOUBLE PRECISION,
    PRIMARY KEY (exercise_id, device_class, metric)
);
