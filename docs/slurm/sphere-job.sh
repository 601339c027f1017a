#!/bin/bash
# SLURM template for sphere: starts a run, or continues it, and requeues itself until it is done.
#
#   sbatch --export=ALL,CASE=configs/demo.toml,RUN_DIR=runs/demo docs/slurm/sphere-job.sh
#   sbatch --array=1-20 --export=ALL,CASE=cases/bed.toml docs/slurm/sphere-job.sh   # one seed per task
#
# Shortly before the time limit SLURM sends SIGUSR1 to this script, which passes it on to sphere;
# sphere writes a checkpoint and exits 75. The script then requeues the job, and the next start
# runs `sphere resume`, which continues bitwise identically. See docs/user-guide.md, section 7.
#
# To stop the chain: `scancel JOBID`. Its SIGTERM makes sphere checkpoint too, but after a
# SIGTERM the script does not requeue; a later sbatch of the same command continues the run.
#
#SBATCH --job-name=sphere
#SBATCH --ntasks=1
#SBATCH --cpus-per-task=8
#SBATCH --time=24:00:00
#SBATCH --signal=B:USR1@300
#SBATCH --requeue
#SBATCH --open-mode=append
#SBATCH --output=sphere-%x-%j.out

set -u

CASE=${CASE:?set CASE to the case file, e.g. sbatch --export=ALL,CASE=case.toml ...}
SPHERE=${SPHERE:-sphere}   # or the full path, e.g. $HOME/sphere/.venv/bin/sphere
name=$(basename "$CASE" .toml)

# Ensemble member: a copy of the case with its own seed and its own run directory (once: a
# resubmitted member, SPHERE_SEEDED=1, already has both).
if [ -n "${SLURM_ARRAY_TASK_ID:-}" ] && [ -z "${SPHERE_SEEDED:-}" ]; then
    seed=$SLURM_ARRAY_TASK_ID
    member="$(dirname "$CASE")/$name-seed$seed.toml"
    if [ ! -f "$member" ]; then
        if [ "$(grep -cE '^[[:space:]]*seed[[:space:]]*=' "$CASE")" != 1 ]; then
            echo "sphere-job: $CASE must hold exactly one line 'seed = ...' (in [particles])" >&2
            exit 65
        fi
        sed -E "s/^([[:space:]]*seed[[:space:]]*=).*/\1 $seed/" "$CASE" > "$member"
    fi
    CASE=$member
    RUN_DIR=${RUN_DIR:-runs}/$name-seed$seed
else
    RUN_DIR=${RUN_DIR:-runs/$name}
fi

# Exactly the CPUs SLURM gave this task (sphere's results do not depend on the count).
export NUMBA_NUM_THREADS=${SLURM_CPUS_PER_TASK:-1}
export OMP_NUM_THREADS=$NUMBA_NUM_THREADS
# OpenMP threads spin while waiting: right on cores of their own, very slow on shared cores
export OMP_WAIT_POLICY=${OMP_WAIT_POLICY:-ACTIVE}

if [ -f "$RUN_DIR/case.toml" ]; then
    "$SPHERE" resume "$RUN_DIR" &
else
    "$SPHERE" run "$CASE" -o "$RUN_DIR" &
fi
pid=$!

# Pass SIGUSR1 (from --signal, before the time limit) and SIGTERM (scancel) on to sphere, which
# checkpoints on either; only the first means "requeue".
signalled=0
cancelled=0
trap 'signalled=1; kill -USR1 "$pid" 2>/dev/null' USR1
trap 'signalled=1; cancelled=1; kill -USR1 "$pid" 2>/dev/null' TERM
while :; do
    wait "$pid"
    rc=$?
    # A trapped signal interrupts `wait` (status > 128) while sphere is still writing its
    # checkpoint: wait again for sphere's own exit status.
    if [ "$signalled" = 1 ] && [ "$rc" -gt 128 ]; then
        signalled=0
        continue
    fi
    break
done

if [ "$rc" -eq 75 ] && [ "$cancelled" = 1 ]; then
    echo "sphere-job: cancelled (SIGTERM); checkpoint written, not requeued: sbatch again to continue"
elif [ "$rc" -eq 75 ]; then
    echo "sphere-job: stopped early with a checkpoint (exit 75); requeueing"
    job=$SLURM_JOB_ID
    if [ -n "${SLURM_ARRAY_TASK_ID:-}" ]; then
        job=${SLURM_ARRAY_JOB_ID}_${SLURM_ARRAY_TASK_ID}
    fi
    if scontrol requeue "$job"; then
        exit 0  # the segment did what it should: sacct lists it as REQUEUED, not FAILED
    fi
    # Requeueing not allowed here: submit this script again, as a plain job, for the same case
    # and run directory. An array task's variables must not reach it (it would seed its seeded
    # case again, in a run directory inside its own): removed, and SPHERE_SEEDED marks it.
    script=$(scontrol show job "$SLURM_JOB_ID" | sed -nE 's/^[[:space:]]*Command=([^ ]*).*/\1/p')
    if env -u SLURM_ARRAY_TASK_ID -u SLURM_ARRAY_JOB_ID SPHERE_SEEDED=1 \
        sbatch --export=ALL,CASE="$CASE",RUN_DIR="$RUN_DIR",SPHERE="$SPHERE",SPHERE_SEEDED=1 "$script"; then
        exit 0
    fi
    echo "sphere-job: could neither requeue nor resubmit; continue with: sphere resume $RUN_DIR" >&2
fi
exit "$rc"
