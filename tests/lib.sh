# Shared by the shell tests (sourced): a temporary folder removed on exit (with the server
# started in $server_pid stopped first), fail() counting failures and finish() reporting them,
# mpirun (an array) for MPIEXEC, the URL a server prints, and the options that write every
# step into a folder with the server off.
#   . "$(dirname "$0")/../lib.sh"; test_setup [MPIEXEC]
test_setup() {
  tmp=$(mktemp -d)
  server_pid=
  trap '[ -n "$server_pid" ] && kill "$server_pid" 2>/dev/null && wait "$server_pid" 2>/dev/null; rm -rf "$tmp"' EXIT
  failures=0
  if [ $# -gt 0 ]; then
    mpirun=("$1" --oversubscribe)
    [ "$(id -u)" = 0 ] && mpirun+=(--allow-run-as-root)
  fi
}
fail() { echo "FAIL: $*"; failures=$((failures + 1)); }
finish() {
  [ "$failures" -eq 0 ] || { echo "$failures failure(s)"; exit 1; }
  echo "PASS"
}

# The first URL FILE holds (a server's start line), waiting up to 10 s; empty if none came.
wait_for_url() {
  local url=
  for _ in $(seq 100); do
    url=$(grep -o 'http://[^ ]*' "$1" 2>/dev/null | head -n 1)
    [ -n "$url" ] && break
    sleep 0.1
  done
  echo "$url"
}

# An options file (its path printed) that writes every published step into DIR, server off,
# waiting steps coalesced; EXTRA (', "key": value') is appended to the document.
writing_options() {
  printf '{"server": {"enabled": false}, "output_dir": "%s", "resolution": %s, "busy": "coalesce"%s}\n' \
    "$1" "${RESOLUTION:-128}" "${2:-}" >"$1.json"
  echo "$1.json"
}
