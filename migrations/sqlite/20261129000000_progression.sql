-- Proficiency-based progression (issue 44): in a curriculum with progression, an exercise
-- opens to a trainee when the exercise before it is proficient, or when an instructor opens
-- it early (recorded here, who and when). A curriculum made before this has none.
ALTER TABLE curricula ADD COLUMN progression BOOLEAN NOT NULL DEFAULT FALSE;

CREATE TABLE exercise_openings (
    id INTEGER PRIMARY KEY,
    trainee_id BIGINT NOT NULL REFERENCES users (id) ON DELETE CASCADE,
    exercise_id BIGINT NOT NULL REFERENCES exercises (id) ON DELETE CASCADE,
    opened_by BIGINT NOT NULL REFERENCES users (id),
    reason TEXT NOT NULL DEFAULT '',
    opened_ns BIGINT NOT NULL,
    UNIQUE (trainee_id, exercise_id)
);
