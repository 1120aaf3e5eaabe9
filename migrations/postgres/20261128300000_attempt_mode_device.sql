-- A fair score for a person (issue 41): how a station attempt was made, so that its verdict
-- is read with it. `mode`: `guided` (the plan shown) or `exam`; `device`: the input, as the
-- station names it (`pointer` for the page's mouse or pen, `expert`, `igtl:18944`...).
-- NULL: not recorded (an attempt from before, or one assessed from a file).
ALTER TABLE attempts ADD COLUMN mode TEXT;
ALTER TABLE attempts ADD COLUMN device TEXT;
