# Sourced by the test servers' scripts: free_port [OTHER] prints a loopback TCP port that no
# socket uses now (and that differs from OTHER).
free_port() {
  local p
  for _ in $(seq 200); do
    p=$(( 20000 + (RANDOM * 32768 + RANDOM) % 40000 ))
    [ "$p" != "${1:-}" ] && ! ss -Htan "( sport = :$p )" | grep -q . && { echo "$p"; return; }
  done
  return 1
}
