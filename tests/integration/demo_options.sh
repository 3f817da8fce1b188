#!/bin/sh
# deploy_demo_options: `deploy/demo --help` prints its usage and exits 0 without installing or
# building anything, and an unknown option is refused on stderr with exit 2. Both run with a PATH
# that holds only the few tools a shell script needs to print (no cmake, apt-get, dpkg-query,
# unshare): a demo that tried to install, build or start anything would fail here.
# Usage: demo_options.sh REPO
set -u
repo=$1
bin=$(mktemp -d)
trap 'rm -rf "$bin"' EXIT
for tool in bash sh sed dirname cat; do ln -s "$(command -v "$tool")" "$bin/$tool"; done
fail=0
out=$(PATH=$bin "$repo/deploy/demo" --help 2>"$bin/err")
rc=$?
[ "$rc" -eq 0 ] || { echo "deploy/demo --help: exit $rc, stderr: $(cat "$bin/err")"; fail=1; }
printf '%s\n' "$out" | grep -q '^Usage:' || { echo "deploy/demo --help: no usage on stdout"; fail=1; }
printf '%s\n' "$out" | grep -q 'deploy/demo --offline' || { echo "deploy/demo --help: --offline not described"; fail=1; }
printf '%s\n' "$out" | grep -q 'deploy/demo --ros2' || { echo "deploy/demo --help: --ros2 not described"; fail=1; }
[ -s "$bin/err" ] && { echo "deploy/demo --help wrote to stderr: $(cat "$bin/err")"; fail=1; }
out=$(PATH=$bin "$repo/deploy/demo" --no-such-option 2>"$bin/err")
rc=$?
[ "$rc" -eq 2 ] || { echo "deploy/demo --no-such-option: exit $rc, expected 2"; fail=1; }
[ -z "$out" ] || { echo "deploy/demo --no-such-option wrote to stdout: $out"; fail=1; }
grep -q "unknown option '--no-such-option'" "$bin/err" ||
  { echo "deploy/demo --no-such-option: stderr does not name the option: $(cat "$bin/err")"; fail=1; }
# rcal-up --ros2 without --demo, and --ros2 with --sim: refused before anything starts.
out=$(PATH=$bin "$repo/deploy/rcal-up" --ros2 2>"$bin/err")
rc=$?
[ "$rc" -eq 2 ] || { echo "rcal-up --ros2: exit $rc, expected 2"; fail=1; }
grep -q "an option of --demo" "$bin/err" || { echo "rcal-up --ros2: $(cat "$bin/err")"; fail=1; }
out=$(PATH=$bin "$repo/deploy/rcal-up" --demo --ros2 --sim x.sim.yaml 2>"$bin/err")
rc=$?
[ "$rc" -eq 2 ] || { echo "rcal-up --demo --ros2 --sim: exit $rc, expected 2"; fail=1; }
# rcal-up --demo --sim with a sim file that is not there: refused before anything starts.
out=$(PATH=$bin "$repo/deploy/rcal-up" --demo --sim /no/such.sim.yaml 2>"$bin/err")
rc=$?
[ "$rc" -eq 2 ] || { echo "rcal-up --demo --sim /no/such.sim.yaml: exit $rc, expected 2"; fail=1; }
grep -q "no/such.sim.yaml: no such file" "$bin/err" ||
  { echo "rcal-up --sim: stderr does not name the file: $(cat "$bin/err")"; fail=1; }
out=$(PATH=$bin "$repo/deploy/rcal-up" --sim "$repo/config/cells/panda.sim.yaml" 2>"$bin/err")
rc=$?
[ "$rc" -eq 2 ] || { echo "rcal-up --sim without --demo: exit $rc, expected 2"; fail=1; }
# --step-offset: described, needs its value, only with --demo, not through ROS 2, and no shell
# metacharacters reach the process table.
printf '%s\n' "$(PATH=$bin "$repo/deploy/demo" --help 2>&1)" | grep -q 'deploy/demo --step-offset' ||
  { echo "deploy/demo --help: --step-offset not described"; fail=1; }
for args in "demo --step-offset" "rcal-up --step-offset j2=1e-3@25" \
            "rcal-up --demo --ros2 --step-offset j2=1e-3@25" "rcal-up --demo --step-offset j2=1e-3@25;rm" \
            "rcal-up --demo --step-offset"; do
  # shellcheck disable=SC2086
  out=$(PATH=$bin "$repo/deploy/"$args 2>"$bin/err")
  rc=$?
  [ "$rc" -eq 2 ] || { echo "$args: exit $rc, expected 2 ($(cat "$bin/err"))"; fail=1; }
  grep -q "step-offset" "$bin/err" || { echo "$args: stderr does not name --step-offset: $(cat "$bin/err")"; fail=1; }
done
# --follow-next-poses: described, only with --demo, not through ROS 2, not with --step-offset.
printf '%s\n' "$(PATH=$bin "$repo/deploy/demo" --help 2>&1)" | grep -q 'deploy/demo --follow-next-poses' ||
  { echo "deploy/demo --help: --follow-next-poses not described"; fail=1; }
for args in "rcal-up --follow-next-poses" "rcal-up --demo --ros2 --follow-next-poses" \
            "rcal-up --demo --follow-next-poses --step-offset j2=1e-3@25" "demo --follow-next-poses x"; do
  # shellcheck disable=SC2086
  out=$(PATH=$bin "$repo/deploy/"$args 2>"$bin/err")
  rc=$?
  [ "$rc" -eq 2 ] || { echo "$args: exit $rc, expected 2 ($(cat "$bin/err"))"; fail=1; }
  grep -q "follow-next-poses\|unknown option" "$bin/err" || { echo "$args: stderr does not name --follow-next-poses: $(cat "$bin/err")"; fail=1; }
done
# --effects: described, takes no value.
printf '%s\n' "$(PATH=$bin "$repo/deploy/demo" --help 2>&1)" | grep -q 'deploy/demo --effects' ||
  { echo "deploy/demo --help: --effects not described"; fail=1; }
out=$(PATH=$bin "$repo/deploy/demo" --effects x 2>"$bin/err")
rc=$?
[ "$rc" -eq 2 ] || { echo "demo --effects x: exit $rc, expected 2 ($(cat "$bin/err"))"; fail=1; }
grep -q "effects takes no value" "$bin/err" || { echo "demo --effects x: $(cat "$bin/err")"; fail=1; }
[ "$fail" = 0 ] && echo "ok: deploy/demo --help and a bad option, rcal-up --sim refusals, nothing installed or built"
exit $fail
