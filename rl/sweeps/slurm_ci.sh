#!/usr/bin/env bash
# Runs rl/sweeps/slurm_array.sh on a real one-node Slurm cluster on this machine (CI runs it
# from test.sh) and checks that a sweep split over an array job, with one task requeued in
# the middle of its run, ends with every run finished and reported:
#
#   cargo build --release -p rl --bin meben
#   rl/sweeps/slurm_ci.sh                 # or: MEBEN=/path/to/meben rl/sweeps/slurm_ci.sh
#
# 1. Installs Debian's slurm-wlm and munge when they are missing (as root, with apt-get);
#    fails when it cannot: the check is never skipped.
# 2. Starts its own munged, slurmctld and slurmd (Slurm 22.05) on localhost, everything
#    (munge key and socket, slurm.conf, state, spool, logs) in a private temporary
#    directory, on two free ports; no cgroups (proctrack/linuxproc, task/none), so it runs
#    in a container. Nothing under /etc is changed and no system daemon is touched.
# 3. Submits slurm_array.sh as a 3-task array (`sbatch --array=1-3`, one CPU each) on a tiny
#    sweep of three short runs (mlp_hn on team_reach/1_ant, seeds 0-2, the quick preset with
#    a budget of a few seconds and a checkpoint every iteration): shard k of 3 is seed k-1.
# 4. Once task 1's run has a checkpoint and is not finished, requeues it
#    (`scontrol requeue`): Slurm stops it (SIGTERM: meben checkpoints and exits) and runs it
#    again. Slurm holds a requeued job back for two minutes; the check sets its start time
#    to now so as not to wait.
# 5. Waits for the array (deadline SLURM_CI_DEADLINE_S, default 600 s) and checks: every task
#    COMPLETED with exit code 0; every run has done.json and one metrics row per iteration
#    (no row twice); task 1 trained, was interrupted, then resumed from its checkpoint (its
#    log, the sweep's last line and a second builds.csv row that goes on from a later
#    iteration); each task's last line is the sweep's sentence ("meben: sweep <out>: 1 run:
#    1 trained, 0 resumed, 0 already done"); `meben report` covers the three seeds.
# 6. Stops every job and daemon it started (trap on EXIT, passed or failed) and checks that
#    no process it started is left. On failure it prints the task and daemon logs and keeps
#    the temporary directory (SLURM_CI_KEEP=1 keeps it after a pass too).
set -euo pipefail
cd "$(dirname "$0")/../.."
root=$PWD
MEBEN=${MEBEN:-${CARGO_TARGET_DIR:-$root/target}/release/meben}
deadline_s=${SLURM_CI_DEADLINE_S:-600}
# The daemons and Slurm's commands live in /usr/sbin, which a user's PATH may lack.
export PATH="$PATH:/usr/sbin:/sbin"
# Run inside a Slurm job or with sbatch defaults set, the variables would reach this cluster.
for name in $(compgen -e); do
    case "$name" in SLURM_* | SBATCH_* | SRUN_* | SALLOC_* | SQUEUE_* | SINFO_*) unset "$name" ;; esac
done

say() { echo "slurm_ci: $*" >&2; }
die() {
    say "FAILED: $*"
    exit 1
}

case "$MEBEN" in /*) ;; *) MEBEN=$root/$MEBEN ;; esac
[ -x "$MEBEN" ] || die "no meben binary at $MEBEN (build it: cargo build --release -p rl --bin meben, or set MEBEN)"

# --- 1. Slurm and munge ------------------------------------------------------------------
tools=(munged munge unmunge slurmctld slurmd sbatch squeue sinfo scontrol scancel srun)
missing() {
    local t
    for t in "${tools[@]}"; do command -v "$t" >/dev/null 2>&1 || return 0; done
    return 1
}
if missing; then
    if [ "$(id -u)" = 0 ] && command -v apt-get >/dev/null 2>&1; then
        say "installing slurm-wlm and munge"
        export DEBIAN_FRONTEND=noninteractive
        apt-get install -y slurm-wlm munge || { apt-get update && apt-get install -y slurm-wlm munge; } ||
            die "could not install slurm-wlm and munge with apt-get"
    fi
    if missing; then
        die "Slurm or munge is missing (need: ${tools[*]}); install them (Debian: sudo apt-get install slurm-wlm munge) and run again"
    fi
fi
[ "$(id -u)" = 0 ] || die "the one-node cluster runs its daemons as root (SlurmUser=root); run as root"

# --- 2. The cluster ----------------------------------------------------------------------
# Under /tmp whatever TMPDIR says: munge's socket path must stay short (at most 108 bytes).
tmp=$(mktemp -d /tmp/meben-slurm-ci.XXXXXX)
# munged wants every directory above its socket searchable by all, and none writable by others.
chmod 755 "$tmp"
mkdir -p "$tmp/munge" "$tmp/state" "$tmp/spool" "$tmp/log" "$tmp/tasks"
export SLURM_CONF=$tmp/slurm.conf
# Every process this check starts (daemons, slurmstepd, the tasks) inherits this marker: the
# last step of the clean-up finds any of them still alive by it, and only them.
export MEBEN_SLURM_CI=$tmp
jobid=
started=

# Processes (not this shell) whose environment holds this check's marker.
marked_processes() {
    local e pid kv
    for e in /proc/[0-9]*/environ; do
        pid=${e#/proc/}
        pid=${pid%/environ}
        [ "$pid" = "$$" ] && continue
        # Builtins only: a child of this shell would carry the marker itself.
        while IFS= read -r -d '' kv; do
            if [ "$kv" = "MEBEN_SLURM_CI=$tmp" ]; then
                echo "$pid"
                break
            fi
        done 2>/dev/null <"$e" || true
    done
}

# Sends `signal` to the pid in `file` and waits up to `wait_s` seconds for it to end.
stop_pidfile() {
    local file=$1 signal=$2 wait_s=$3 pid i
    [ -s "$file" ] || return 0
    pid=$(cat "$file")
    kill -0 "$pid" 2>/dev/null || return 0
    kill "-$signal" "$pid" 2>/dev/null || true
    for ((i = 0; i < wait_s * 10; i++)); do
        kill -0 "$pid" 2>/dev/null || return 0
        sleep 0.1
    done
    return 1
}

print_logs() {
    local f
    for f in "$tmp"/tasks/*.out "$tmp"/log/slurmctld.log "$tmp"/log/slurmd.log "$tmp"/munge/munged.log; do
        [ -f "$f" ] || continue
        echo "----- $f (last 60 lines)" >&2
        tail -n 60 "$f" >&2
    done
}

cleanup() {
    local status=$? pids pid i
    set +e
    trap - EXIT INT TERM
    [ "$status" = 0 ] || print_logs
    if [ -n "$started" ]; then
        # The jobs first (slurmd ends their processes), then the daemons.
        if [ -n "$jobid" ]; then
            scancel "$jobid" 2>/dev/null
            for ((i = 0; i < 300; i++)); do
                [ -z "$(squeue -h -j "$jobid" 2>/dev/null)" ] && break
                sleep 0.1
            done
        fi
        scontrol shutdown >/dev/null 2>&1
        stop_pidfile "$tmp/slurmctld.pid" TERM 20 || stop_pidfile "$tmp/slurmctld.pid" KILL 5
        stop_pidfile "$tmp/slurmd.pid" TERM 20 || stop_pidfile "$tmp/slurmd.pid" KILL 5
    fi
    stop_pidfile "$tmp/munge/munged.pid" TERM 10 || stop_pidfile "$tmp/munge/munged.pid" KILL 5
    # Anything of this check still alive (a task slurmd could not end) is ended and named.
    pids=$(marked_processes)
    if [ -n "$pids" ]; then
        say "processes left running, now killed: $(echo "$pids" | tr '\n' ' ')"
        # shellcheck disable=SC2086
        kill -KILL $pids 2>/dev/null
        sleep 0.5
        [ "$status" = 0 ] && status=1
    fi
    pids=$(marked_processes)
    if [ -n "$pids" ]; then
        say "FAILED: processes still running after the clean-up: $pids"
        [ "$status" = 0 ] && status=1
    fi
    if [ "$status" = 0 ] && [ -z "${SLURM_CI_KEEP:-}" ]; then
        rm -rf "$tmp"
    else
        say "kept $tmp (slurm.conf, logs, the sweep's output)"
    fi
    exit "$status"
}
trap cleanup EXIT
trap 'exit 130' INT
trap 'exit 143' TERM

# Two free consecutive TCP ports (nothing listening on 127.0.0.1) for slurmctld and slurmd.
port_free() { ! (exec 3<>"/dev/tcp/127.0.0.1/$1") 2>/dev/null; }
port=$((20000 + RANDOM % 20000))
for ((i = 0; i < 200; i++)); do
    port_free "$port" && port_free $((port + 1)) && break
    port=$((port + 2))
done
if ! { port_free "$port" && port_free $((port + 1)); }; then
    die "no two free TCP ports found for slurmctld and slurmd"
fi

# The munge key: 1024 random bytes, readable by its owner only (root, who runs munged).
if command -v mungekey >/dev/null 2>&1; then
    mungekey --create --keyfile="$tmp/munge/munge.key" || die "mungekey could not create a key"
else
    dd if=/dev/urandom of="$tmp/munge/munge.key" bs=1024 count=1 status=none || die "could not create a munge key"
fi
chmod 600 "$tmp/munge/munge.key"
sock=$tmp/munge/munge.socket
munged --socket="$sock" --key-file="$tmp/munge/munge.key" --pid-file="$tmp/munge/munged.pid" \
    --log-file="$tmp/munge/munged.log" --seed-file="$tmp/munge/munged.seed" ||
    die "munged did not start (log: $tmp/munge/munged.log)"
munge -n -S "$sock" | unmunge -S "$sock" >/dev/null || die "munge cannot encode and decode a credential"

cpus=$(nproc)
mem_mb=$(awk '/^MemTotal:/ { print int($2 / 1024 * 0.9) }' /proc/meminfo)
task_mem_mb=512
((mem_mb >= 3 * task_mem_mb)) || die "the node has ${mem_mb} MB for Slurm, less than 3 tasks x ${task_mem_mb} MB"
cat >"$SLURM_CONF" <<EOF
# A one-node cluster on localhost for rl/sweeps/slurm_ci.sh (written by it).
ClusterName=mebenci
SlurmctldHost=localhost
SlurmctldPort=$port
SlurmdPort=$((port + 1))
SlurmUser=root
SlurmdUser=root
AuthType=auth/munge
AuthInfo=socket=$sock
CredType=cred/munge
StateSaveLocation=$tmp/state
SlurmdSpoolDir=$tmp/spool
SlurmctldPidFile=$tmp/slurmctld.pid
SlurmdPidFile=$tmp/slurmd.pid
SlurmctldLogFile=$tmp/log/slurmctld.log
SlurmdLogFile=$tmp/log/slurmd.log
# No cgroups (a container has none to give): processes tracked by parent id, no binding.
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
JobAcctGatherType=jobacct_gather/none
AccountingStorageType=accounting_storage/none
JobCompType=jobcomp/none
MpiDefault=none
SwitchType=switch/none
SchedulerType=sched/builtin
SelectType=select/cons_tres
SelectTypeParameters=CR_CPU_Memory
# The node is what this file says (a container's hardware detection may differ).
SlurmdParameters=config_overrides
JobRequeue=1
ReturnToService=2
# Finished jobs stay visible to scontrol for the checks.
MinJobAge=600
NodeName=localhost CPUs=$cpus RealMemory=$mem_mb State=UNKNOWN
PartitionName=ci Nodes=localhost Default=YES MaxTime=INFINITE State=UP
EOF
started=1
slurmctld -f "$SLURM_CONF" || die "slurmctld did not start"
slurmd -f "$SLURM_CONF" -N localhost || die "slurmd did not start"
say "one-node cluster up: $SLURM_CONF (ports $port, $((port + 1)), $cpus CPUs, $mem_mb MB)"
for ((i = 0; ; i++)); do
    state=$(sinfo -h -n localhost -o %T 2>/dev/null || true)
    [ "$state" = idle ] && break
    ((i < 600)) || die "the node is not idle after 60 s (sinfo: '${state}')"
    sleep 0.1
done

# --- 3. The sweep ------------------------------------------------------------------------
# 3 runs, shard k of 3 = seed k-1. 80 env steps an iteration (batch_size x num_minibatches x
# unroll_length = 4 x 4 x 5), 40 iterations: a few seconds a run, a checkpoint every one.
iterations=40
sweep=$tmp/sweep.toml
out=$tmp/out
cat >"$sweep" <<EOF
envs = ["team_reach/1_ant"]
models = ["mlp_hn"]
seeds = [0, 1, 2]
preset = "quick"

[config]
num_envs = 8
batch_size = 4
num_minibatches = 4
unroll_length = 5
epochs = 1
steps = $((iterations * 80))
num_evals = 2
eval_episodes = 2
checkpoint_every = 1
threads = 1
EOF
run_dir() { echo "$out/team_reach_1_ant/mlp_hn/seed$(($1 - 1))"; }

# slurm_array.sh reads SWEEP, OUT and MEBEN; sbatch passes the environment on. The options
# given here replace the script's #SBATCH lines (16 CPUs and 16G per task, 8 tasks).
jobid=$(SWEEP=$sweep OUT=$out MEBEN=$MEBEN sbatch --parsable --array=1-3 --cpus-per-task=1 \
    --mem="${task_mem_mb}M" --time=00:15:00 --chdir="$tmp" --open-mode=append \
    --output="$tmp/tasks/task-%a.out" "$root/rl/sweeps/slurm_array.sh") || die "sbatch failed"
jobid=${jobid%%;*}
say "submitted array job $jobid (3 tasks) on $sweep"
t0=$SECONDS

# --- 4. Requeue task 1 in the middle of its run ------------------------------------------
# A task's JobState (PENDING, RUNNING, COMPLETED, FAILED, ...).
task_state() {
    local info
    info=$(scontrol -o show job "${jobid}_$1" 2>/dev/null || true)
    [[ $info =~ JobState=([A-Z_]+) ]] && echo "${BASH_REMATCH[1]}"
    return 0
}
rows() { if [ -f "$1/metrics.csv" ]; then echo $(($(wc -l <"$1/metrics.csv") - 1)); else echo 0; fi; }
victim=$(run_dir 1)
while :; do
    state=$(task_state 1)
    if [ "$state" = RUNNING ] && [ -f "$victim/checkpoint.json" ] && [ ! -f "$victim/done.json" ] &&
        (($(rows "$victim") >= 2)); then
        break
    fi
    [ -f "$victim/done.json" ] && die "task 1's run finished before it could be requeued (make the runs longer)"
    case "$state" in PENDING | CONFIGURING | RUNNING | "") ;; *) die "task 1 ended ($state) before its run wrote a checkpoint" ;; esac
    ((SECONDS - t0 < deadline_s)) || die "task 1's run wrote no checkpoint within ${deadline_s} s"
    sleep 0.1
done
at=$(rows "$victim")
scontrol requeue "${jobid}_1" || die "scontrol requeue ${jobid}_1 failed"
say "requeued task 1 at iteration ~$at of $iterations ($((SECONDS - t0)) s after submission)"
# A requeued job becomes eligible two minutes later; start it as soon as it is pending.
while :; do
    state=$(task_state 1)
    if [ "$state" = PENDING ] && scontrol update JobId="${jobid}_1" StartTime=now 2>/dev/null; then
        break
    fi
    [ "$state" = RUNNING ] && grep -q resuming "$tmp/tasks/task-1.out" 2>/dev/null && break
    ((SECONDS - t0 < deadline_s)) || die "task 1 was not pending again within ${deadline_s} s of submission"
    sleep 0.2
done

# --- 5. Wait and check -------------------------------------------------------------------
while [ -n "$(squeue -h -j "$jobid" 2>/dev/null)" ]; do
    ((SECONDS - t0 < deadline_s)) || die "the array job did not finish within ${deadline_s} s"
    sleep 0.5
done
say "array job $jobid finished $((SECONDS - t0)) s after submission; checking"

fail=0
bad() {
    say "FAILED: $*"
    fail=1
}
for k in 1 2 3; do
    info=$(scontrol -o show job "${jobid}_$k" 2>/dev/null || true)
    [[ $info == *"JobState=COMPLETED "* && $info == *" ExitCode=0:0 "* ]] ||
        bad "task $k did not complete with exit code 0: $(grep -o 'JobState=[^ ]*\|ExitCode=[^ ]*' <<<"$info" | tr '\n' ' ')"
    dir=$(run_dir "$k")
    log=$tmp/tasks/task-$k.out
    [ -f "$dir/done.json" ] || bad "run $dir has no done.json"
    # One metrics row per iteration, 1..N in order: a resumed run repeats none.
    got=$(awk -F, 'NR == 1 { for (i = 1; i <= NF; i++) if ($i == "iteration") c = i; next }
        { if ($c != NR - 1) { print "row " NR - 1 " is iteration " $c; exit } } END { if (c == 0) print "no iteration column" }' \
        "$dir/metrics.csv" 2>&1)
    [ -z "$got" ] || bad "$dir/metrics.csv: $got"
    [ "$(rows "$dir")" = "$iterations" ] || bad "$dir/metrics.csv has $(rows "$dir") rows, not $iterations"
    last=$(tail -n 1 "$log" 2>/dev/null)
    if [ "$k" = 1 ]; then
        want="meben: sweep $out: 1 run: 0 trained, 1 resumed, 0 already done"
        # Trained, interrupted by the requeue, then resumed from the checkpoint.
        order=$(grep -o ': training$\|meben: interrupted\|: resuming$' "$log" | tr '\n' ' ')
        [ "$order" = ": training meben: interrupted : resuming " ] ||
            bad "task 1's log does not show training, the interruption, then resuming (saw: $order)"
        # builds.csv: a row per session; the second goes on from the iteration the
        # interrupted one checkpointed ("interrupted after iteration N, which its checkpoint holds").
        stopped=$(sed -n 's/.*: interrupted after iteration \([0-9]*\), which its checkpoint holds.*/\1/p' "$log" | head -n 1)
        from=$(awk -F, 'NR == 1 { for (i = 1; i <= NF; i++) if ($i == "from_iteration") c = i; next } { print $c }' \
            "$dir/builds.csv" 2>/dev/null | tr '\n' ' ')
        if [ -z "$stopped" ] || ((stopped >= iterations)) || [ "$from" != "0 $stopped " ]; then
            bad "task 1's run should have stopped at a checkpoint before iteration $iterations and resumed from it" \
                "(stopped after: '${stopped}'; builds.csv sessions from iterations: $from)"
        fi
    else
        want="meben: sweep $out: 1 run: 1 trained, 0 resumed, 0 already done"
    fi
    [ "$last" = "$want" ] || bad "task $k's last line is '$last', not '$want'"
    ! grep -q SweepOutcome "$log" || bad "task $k's log prints SweepOutcome"
done

report=$("$MEBEN" report "$out" 2>"$tmp/report.err") || bad "meben report failed: $(cat "$tmp/report.err")"
# One group (mlp_hn on team_reach/1_ant) of three seeds, each with its final value.
groups=$(awk -F, 'NR == 1 { for (i = 1; i <= NF; i++) { if ($i == "seeds") c = i; if ($i == "seed_list") l = i }; next }
    { print $c ":" $l }' "$out/report.csv" 2>/dev/null | tr '\n' ' ')
[ "$groups" = "3:0 1 2 " ] || bad "report.csv should have one group of seeds 0 1 2 (saw: '$groups')"
grep -q "mlp_hn" <<<"$report" || bad "the report does not show mlp_hn"
((fail == 0)) || exit 1
tail -n 1 "$tmp/tasks/task-1.out" >&2
say "passed: 3 array tasks COMPLETED, 3 runs done ($iterations iterations each, no row twice); task 1 requeued" \
    "at iteration ~$at, checkpointed after iteration $stopped and resumed from it; the report covers seeds 0 1 2" \
    "($((SECONDS - t0)) s from submission)"
