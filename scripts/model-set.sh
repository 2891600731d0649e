# Sourced by scripts/model-node.sh (the main job) and scripts/replay-job.sh (a job's stored runs
# calibrated again): the validation set's lengths and the model's calibrate, predict and
# validate, so that a replay predicts exactly what the main job predicts. Expects root, build,
# machine, quick (0 or 1), out, runs and stage(); model_and_validate reads the arrays
# cal_reports and val_reports.

# Validation steps per setup and scale, and calibration reach. A calibration run at scale s must
# cover the validation's flow in Froude time (t_cal >= t_val sqrt(s / scale)); c_steps at half
# scale, c35_steps at 0.35 (the 2-thread dam break: 0.089 s, 920 steps). The list and table
# dam breaks at 0.5 (c5_steps) cover the validation's simulated time, 0.1 s (1000 steps of
# 0.1 ms; 1500 in session 59, 0.106 s in sessions 55-58): Cell+Table's memory order follows
# simulated time, and predict carries each slab's to the whole water's there
# (--memory-order-time simulated, sessions 59-89; the model reads each slab's columns at
# simulated time since session 91, which needs the record as far, as does simulated-order/). The models reported beside it may
# select the memory-order term, which needs the same; a prediction they cannot make from these
# runs is listed as such. The scale-1 dam breaks run 1000 steps since session 60 (1500 before):
# on the Zen 3 host of session 60 the job took 10:47-11:33 with 1500 and 9:00-9:56 with 1200,
# its list and table runs about twice as long as on the Intel host before. cs7_steps: Cell+Table's
# still tank at 0.7 (about 10 ms steps), whose wait says how the jitter grows with the step.
# c7s_steps: Cell+Sorted's 1-thread dam break at 0.7, as far in Froude time as the 0.25 one
# (300 sqrt(0.7 / 0.25) = 502 steps), the reach the cost fit's points share. The scale-2 dam
# breaks (v2_steps) run the scale-1 ones' 0.1 s of simulated time since session 90 (0.05 s
# before): the calibration already reaches it (the memory order's record, 0.1 s; the flow, 0.05
# s of Froude time at 0.5), so the same calibration predicts a test twice as long, the
# furthest from its runs in the set (four times the particles of the half-scale record).
if [ "$quick" -eq 1 ]; then
    v_steps=40 v2_steps=20 vs_steps=40 c_steps=200 c5_steps=130 c35_steps=130 c7_steps=60
    c25_steps=60 c7s_steps=100 cs_steps=40 cs7_steps=20 interval=20 c_interval=10
else
    v_steps=1000 v2_steps=1000 vs_steps=300 c_steps=1500 c5_steps=1000 c35_steps=920 c7_steps=300
    c25_steps=300 c7s_steps=500 cs_steps=300 cs7_steps=160 interval=100 c_interval=20
fi
# A replay of a stored job predicts its runs' own length (scripts/replay-job.sh sets it).
v_steps=${REPLAY_V_STEPS:-$v_steps}
v2_steps=${REPLAY_V2_STEPS:-$v2_steps}

# The model sees the calibration runs only; the validation reports are read after predicting.
# model_and_validate DIR RULE PROFILE [WEIGHTS [SHARING]]: calibrate with the compute-cost term
# rule RULE, the time profile PROFILE and the fit weights WEIGHTS (relative unless given),
# predict with the time-sharing form SHARING (replay unless given), validate; with the
# reports listed in the arrays cal_reports and val_reports.
# The model's calibration runs: every round's (rounds a and b, and Cell+Sorted's c).
model_runs() {
    ls "$runs"/cal_*.json
}
model_and_validate() {
    local dir=$1 rule=$2 profile=$3 weights=${4:-relative} sharing=${5:-replay}
    local predict_extra=() cal_extra=()
    [ -n "${6:-}" ] && read -r -a predict_extra <<<"$6"
    # CAL_EXTRA: more calibrate options (a comparison model's).
    [ -n "${CAL_EXTRA:-}" ] && read -r -a cal_extra <<<"$CAL_EXTRA"
    mkdir -p "$dir"
    rm -f "$dir/refused.txt"
    stage "calibration ($rule, time profile $profile)"
    "$build/bin/sphmodel" calibrate --machine "$machine" --runs "${cal_reports[@]}" \
        --term-selection "$rule" --time-profile "$profile" --fit-weights "$weights" \
        "${cal_extra[@]}" --out "$dir/model.json"

    stage "predictions ($rule)"
    # Each slab's memory order from its columns' at the target's simulated time (predict
    # --memory-order-time columns, since session 91): the calibration record's per-column
    # descents at the same simulated time, columns at their relative place, put the 4-rank
    # dam breaks' ranks within 0-8 % of the descents they count, where Froude time (session 90)
    # read the back rank 41 % low at scale 2. Replayed on 92 stored main jobs against Froude
    # time: the 4-rank scale-2 table dam break's mean error +3.9 -> +2.2 %, the jobs' max 0.13
    # points lower (standard error 0.06; model/NOTES.md, session 91): **tuned**. Session 90's
    # rule (froude) and sessions 59-89's (simulated) are validated beside. A comparison
    # model's own --memory-order-time (predict_extra) replaces it.
    local order=(--memory-order-time columns)
    if [[ " ${predict_extra[*]} " == *" --memory-order-time "* ]]; then order=(); fi
    predict() { # predict NAME [--threads T] ARGS... (1 thread per rank unless given)
        local name=$1 threads=1
        shift
        if [ "${1:-}" = "--threads" ]; then threads=$2; shift 2; fi
        # The model in use must predict everything; a comparison model may refuse a
        # configuration its calibration cannot reach (exit 2, its one line kept).
        "$build/bin/sphmodel" predict --model "$dir/model.json" --threads "$threads" \
            --interval "$interval" --time-sharing-overhead "$sharing" "${order[@]}" \
            "${predict_extra[@]}" --out "$dir/prediction_$name.json" "$@" 2>"$dir/$name.err" || {
            local rc=$?
            if [ "$dir" = "$out" ] || [ "$rc" -ne 2 ]; then
                cat "$dir/$name.err" >&2
                return 1
            fi
            echo "  $dir: cannot predict $name: $(cat "$dir/$name.err")" | tee -a "$dir/refused.txt"
        }
        [ -s "$dir/$name.err" ] && cat "$dir/$name.err" >&2
        rm -f "$dir/$name.err"
    }
    # The host speed each prediction is at (predict --host-speed, sessions 75-76): the list and
    # table dam breaks, single runs of 8-30 s that span the host's spells (5-60 s), at the
    # host's mean speed over the calibration runs of their grid and setup, what one run's sum of
    # steps pays; the others, validated as the median of three runs of about 1-7 s
    # (scripts/model-node.sh, short_pass), at the median calibration run's speed, where such a
    # median lands. HOST_SPEED_LONG: the long runs' rule of a comparison model (mean-pooled:
    # session 75's). A comparison model's own --host-speed (predict_extra) sets every prediction's.
    local long=(--host-speed "${HOST_SPEED_LONG:-mean}") short=(--host-speed median)
    if [[ " ${predict_extra[*]} " == *" --host-speed "* ]]; then long=() short=(); fi
    predict dambreak_s1_table "${long[@]}" --setup dambreak --grid table --scale 1 --ranks 1,2,3,4 \
        --steps "$v_steps"
    predict dambreak_s1_table_balanced "${long[@]}" --setup dambreak --grid table --scale 1 \
        --ranks 2,4 --steps "$v_steps" --decomposition balanced
    predict dambreak_s1_list "${long[@]}" --setup dambreak --grid list --scale 1 --ranks 1,2,3 \
        --steps "$v_steps"
    predict dambreak_s2_table "${long[@]}" --setup dambreak --grid table --scale 2 --ranks 2,4 \
        --steps "$v2_steps"
    predict still_s1_table "${short[@]}" --setup still --grid table --scale 1 --ranks 2,3 \
        --steps "$vs_steps"
    predict still_s1_list "${short[@]}" --setup still --grid list --scale 1 --ranks 2 \
        --steps "$vs_steps"
    predict dambreak_s1_sorted "${short[@]}" --setup dambreak --grid sorted --scale 1 --ranks 2 \
        --steps "$v_steps"
    predict still_s1_sorted "${short[@]}" --setup still --grid sorted --scale 1 --ranks 2,3 \
        --steps "$vs_steps"
    predict dambreak_s1_sorted_overlap "${short[@]}" --setup dambreak --grid sorted --overlap \
        --scale 1 --ranks 2 --steps "$v_steps"
    predict still_s1_sorted_overlap "${short[@]}" --setup still --grid sorted --overlap --scale 1 \
        --ranks 2 --steps "$vs_steps"
    predict dambreak_s1_sorted_t2 --threads 2 "${short[@]}" --setup dambreak --grid sorted \
        --scale 1 --ranks 1 --steps "$v_steps"

    stage "validation ($rule)"
    "$build/bin/sphmodel" validate --prediction "$dir"/prediction_*.json \
        --measured "${val_reports[@]}" --out "$dir/validation.json"
}

# in_sample DIR: the model in DIR/model.json predicting its own calibration runs, each
# configuration it ran (setup, grid, scale, ranks, threads, length, interval) at the model's
# reference speed, validated against those runs: DIR/in-sample/validation.json. What the fit
# cannot reproduce even where it was fitted (validate's errors at each run's and each rank's own
# speed) is the model's form, not the extrapolation to runs it never saw (model/NOTES.md,
# session 77). Nothing is run; about a second.
in_sample() {
    local dir=$1 key
    local ins="$dir/in-sample"
    rm -rf "$ins"
    mkdir -p "$ins"
    # One line per calibration configuration: its predict options, the rank counts joined.
    /usr/bin/python3 - "${cal_reports[@]}" >"$ins/configurations.txt" <<'PY'
import json, sys
groups = {}
for path in sys.argv[1:]:
    with open(path) as f:
        c = json.load(f)["config"]
    key = (c["setup"], c["grid"], c["scale"], c["threads"], c["steps"], c["interval"],
           c["delta"], c["dt"], bool(c.get("overlap")))
    groups.setdefault(key, set()).add(int(c["ranks"]))
for (setup, grid, scale, threads, steps, interval, delta, dt, overlap), ranks in sorted(groups.items()):
    print(f"{setup}_{grid}_s{scale:g}_t{threads}_n{steps}{'_overlap' if overlap else ''}",
          f"--setup {setup} --grid {grid} --scale {scale!r} --threads {threads} --steps {steps}",
          f"--interval {interval} --delta {delta!r} --dt {dt!r}{' --overlap' if overlap else ''}",
          "--ranks " + ",".join(str(r) for r in sorted(ranks)))
PY
    while read -r key opts; do
        # shellcheck disable=SC2086 # opts is the option list written above
        "$build/bin/sphmodel" predict --model "$dir/model.json" --host-speed median $opts \
            --out "$ins/prediction_$key.json" >/dev/null
    done <"$ins/configurations.txt"
    "$build/bin/sphmodel" validate --prediction "$ins"/prediction_*.json \
        --measured "${cal_reports[@]}" --out "$ins/validation.json" >"$ins/validation.txt"
}
