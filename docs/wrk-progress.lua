-- wrk script for the dashboard load figures (docs/bench/dashboard.md): cycles the progress page (or,
-- with PREFIX=/api, the progress API) over the trainees FIRST..LAST, logged in by the
-- session cookie COOKIE. Usage:
--   COOKIE=<token> FIRST=2 LAST=101 PREFIX= wrk -t2 -c200 -d10s --latency -s docs/wrk-progress.lua http://127.0.0.1:8099
local first = tonumber(os.getenv("FIRST") or "2")
local last = tonumber(os.getenv("LAST") or "101")
local prefix = os.getenv("PREFIX") or ""
local suffix = prefix == "/api" and "/progress" or ""
wrk.headers["Cookie"] = "cutlab_session=" .. (os.getenv("COOKIE") or "")
local n = 0
request = function()
  local id = first + n % (last - first + 1)
  n = n + 1
  return wrk.format("GET", prefix .. "/trainees/" .. id .. suffix)
end
