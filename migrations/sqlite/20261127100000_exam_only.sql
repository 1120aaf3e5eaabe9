-- An exercise may force exam mode at the station (issue 29): the planned incision is never
-- shown on the tissue, whatever the trainee picks.
ALTER TABLE exercises ADD COLUMN exam_only BOOLEAN NOT NULL DEFAULT FALSE;
