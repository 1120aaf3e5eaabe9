-- Validity evidence (issue 45). A user's surgical experience, set by an administrator: the
-- groups the evidence report contrasts (NULL: not recorded, left out of the groups).
ALTER TABLE users ADD COLUMN experience TEXT CHECK (experience IN ('novice', 'intermediate', 'expert'));

-- Pass marks on an exercise's overall score set by a standard-setting method, adopted by an
-- instructor (who and when); the newest is the exercise's. The figures are those of the
-- report it was adopted from: the groups contrasted, their sizes, the observed false pass
-- and false fail rates.
CREATE TABLE pass_marks (
    id INTEGER PRIMARY KEY,
    exercise_id BIGINT NOT NULL REFERENCES exercises (id) ON DELETE CASCADE,
    method TEXT NOT NULL CHECK (method IN ('contrasting-groups')),
    score DOUBLE PRECISION NOT NULL,
    higher_group TEXT NOT NULL,
    lower_group TEXT NOT NULL,
    n_higher BIGINT NOT NULL,
    n_lower BIGINT NOT NULL,
    false_pass DOUBLE PRECISION NOT NULL,
    false_fail DOUBLE PRECISION NOT NULL,
    adopted_by BIGINT NOT NULL REFERENCES users (id),
    adopted_ns BIGINT NOT NULL
);
CREATE INDEX pass_marks_by_exercise ON pass_marks (exercise_id, adopted_ns);
