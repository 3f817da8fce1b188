#!/bin/sh
# lcm_spy_check_fails_without_jchart2d: deploy/lcm-spy --check with jchart2d left off lcm-spy's
# classpath (RCAL_JCHART2D_JAR pointed at the rcal types jar, a jar without it) must fail, and fail
# where a user's double-click failed: lcm-spy's NoClassDefFoundError for jchart2d on opening a
# message view. Usage: lcm_spy_without_jchart2d.sh BUILD_DIR DEPLOY_LCM_SPY
set -u
build=$1
spy=$2
out=$(RCAL_JCHART2D_JAR=$build/lcmtypes/rcal_lcmtypes.jar RCAL_BUILD_DIR=$build "$spy" --check 2>&1)
rc=$?
printf '%s\n' "$out" | grep -v '^ClassDiscoverer\|^  '
if [ "$rc" -eq 0 ]; then
  echo "lcm-spy --check passed without jchart2d" >&2
  exit 1
fi
printf '%s\n' "$out" | grep -q 'FAILED: double-click' || { echo "no failed double-click reported" >&2; exit 1; }
printf '%s\n' "$out" | grep -q 'NoClassDefFoundError: info/monitorenter' || {
  echo "the failure is not lcm-spy's NoClassDefFoundError for jchart2d" >&2
  exit 1
}
echo "ok: the check fails without jchart2d, as lcm-spy did"
