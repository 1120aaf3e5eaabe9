-- Review notes (issue 32): an instructor's comment may be pinned to a moment of the attempt,
-- its simulated time in nanoseconds from the recording's start (the replay's `sim_time`);
-- NULL is a comment on the whole attempt.
ALTER TABLE attempt_comments ADD COLUMN at_ns BIGINT;
