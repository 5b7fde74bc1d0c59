#!/usr/bin/env bash
# Hostile-input round: runs the apps on a table of bad (and a few good) inputs and classifies
# each outcome:
#   clear     refused with exit 1 and a message matching the case's expectation
#   sensible  accepted as the case expects (exit 0, and the expected output when one is given)
#   crash     killed by a signal (SIGSEGV, SIGABRT, ...)
#   hang      still running after the time limit
#   silent    exit 0 where the case expects a refusal (a silently wrong result)
#   poor      refused, but with a raw library message or without what the case expects
# Usage: scripts/hostile_round.sh BUILD_DIR [seconds per case, default 120]
# Prints one line per case and the counts; the table is in $work/results.tsv. Exit status 1
# when any case crashed, hung or was silent; poor messages are counted, not fatal.
set -uo pipefail
build=$(cd "${1:?usage: $0 BUILD_DIR [seconds per case]}" && pwd)
limit=${2:-120}
src=$(cd "$(dirname "$0")/.." && pwd)
tools="$src/scripts/hostile"
T="$build/apps/desplat_train" R="$build/apps/desplat_render" Y="$build/apps/desplat_synth"
F="$build/apps/desplat_sfm" O="$build/apps/desplat_occlude" B="$build/apps/desplat_bench"
for exe in "$T" "$R" "$Y" "$F" "$O" "$B"; do [ -x "$exe" ] || { echo "missing $exe (build the apps first)" >&2; exit 2; }; done
work=$(mktemp -d "${TMPDIR:-/tmp}/desplat_hostile_XXXXXX")
trap 'chmod -R u+w "$work" 2>/dev/null; rm -rf "$work"' EXIT
export DESPLAT_CACHE_DIR="$work/cache"
W=$work
cd "$work" || exit 2

# ---- Fixtures: a tiny DeSplat scene, a text copy of its model, models trained on it --------
quiet() { "$@" >"$work/fixture.log" 2>&1 || { echo "fixture failed: $*" >&2; cat "$work/fixture.log" >&2; exit 2; }; }
quiet "$Y" --scene "$src/data/synthetic/tiny_distractors.json" --out "$W/S" -q
quiet "$Y" --scene "$src/data/synthetic/tiny_clean.json" --out "$W/C" -q
mkdir -p "$W/X/sparse/0"
cp -r "$W/S/images" "$W/X/images"
quiet colmap model_converter --input_path "$W/S/sparse/0" --output_path "$W/X/sparse/0" --output_type TXT
train_fast="--iterations 3 --threads 2 --eval-every 0 --log-every 1"
quiet "$T" --data "$W/S" --out "$W/M" $train_fast --effects distractors
quiet "$T" --data "$W/S" --out "$W/MA" $train_fast --effects distractors --split all-train
quiet "$T" --data "$W/C" --out "$W/MC" $train_fast --static-only
quiet "$T" --data "$W/C" --out "$W/MCD" $train_fast --effects distractors
mkdir -p "$W/black_masks" "$W/empty_dir"
echo "not a folder" >"$W/a_file"
ln -s "$W/S" "$W/link_to_S"

# variant NAME EDIT: a copy of the text scene with the model edited by edit_model.py.
variant() { rm -rf "$W/v_$1"; mkdir -p "$W/v_$1"; cp -r "$W/X/sparse" "$W/v_$1/"; ln -s "$W/X/images" "$W/v_$1/images";
            python3 "$tools/edit_model.py" "$W/v_$1/sparse/0" "$2"; echo "$W/v_$1"; }
# ckpt NAME FROM EDIT: a copy of model FROM whose checkpoint edit_checkpoint.py changed.
ckpt() { rm -rf "$W/k_$1"; cp -r "$W/$2" "$W/k_$1"; python3 "$tools/edit_checkpoint.py" "$W/k_$1/checkpoint.ckpt" "$3"; echo "$W/k_$1"; }
# swapped NAME INTO FROM: model INTO with the checkpoint of model FROM.
swapped() { rm -rf "$W/s_$1"; cp -r "$W/$2" "$W/s_$1"; cp "$W/$3/checkpoint.ckpt" "$W/s_$1/"; echo "$W/s_$1"; }
deep() { python3 -c "import sys; n=int(sys.argv[1]); print('{\"a\":'*n + '1' + '}'*n)" "$1"; }
deep_list() { python3 -c "import sys; n=int(sys.argv[1]); print('['*n + ']'*n)" "$1"; }

poor_re='json\.exception|filesystem error|what\(\)|terminate called|Invalid argument \[|basic_string|std::|_M_range|stoi|stod|bad_alloc|Segmentation|Aborted'
declare -A count=([clear]=0 [sensible]=0 [crash]=0 [hang]=0 [silent]=0 [poor]=0)
n=0
printf 'case\tclass\texit\texpected\tfirst line\n' >"$work/results.tsv"
# hostile NAME EXPECT COMMAND: EXPECT is err:REGEX (a refusal whose message matches REGEX),
# ok (exit 0) or ok:REGEX (exit 0 and output matching REGEX).
hostile() {
  local name=$1 expect=$2 cmd=$3 rc class out
  n=$((n + 1))
  out="$work/out_$n.txt"
  timeout -s KILL "$limit" bash -c "$cmd" >"$out" 2>&1 </dev/null
  rc=$?
  if [ $rc -eq 137 ]; then class=hang
  elif [ $rc -gt 128 ]; then class=crash
  elif grep -qE 'Segmentation fault|core dumped' "$out"; then class=crash
  elif [[ $expect == err:* ]]; then
    if [ $rc -eq 0 ]; then class=silent
    elif grep -aqE "$poor_re" "$out"; then class=poor
    elif grep -aqE -- "${expect#err:}" "$out"; then class=clear
    else class=poor; fi
  else
    if [ $rc -ne 0 ]; then class=poor
    elif [[ $expect == ok:* ]] && ! grep -aqE -- "${expect#ok:}" "$out"; then class=silent
    else class=sensible; fi
  fi
  count[$class]=$((count[$class] + 1))
  local first
  first=$(grep -a -m1 -E 'error|warning' "$out" || head -1 "$out")
  printf '%s\t%s\t%s\t%s\t%s\n' "$name" "$class" "$rc" "$expect" "${first:0:300}" >>"$work/results.tsv"
  printf '%-4s %-9s %-44s %s\n' "$n" "$class" "$name" "${first:0:160}"
}

tr="$T $train_fast --effects distractors"  # not auto: its transient probe would add a minute per run
# ---- Output folders: the input, inside it, around it, the root, files, empty ------------------
hostile out_is_data           'err:same folder'        "$tr --data $W/S --out $W/S"
hostile out_is_data_slash     'err:same folder'        "$tr --data $W/S --out $W/S/"
hostile out_is_data_dot       'err:same folder'        "$tr --data $W/S --out $W/S/."
hostile out_is_data_dotdot    'err:same folder'        "$tr --data $W/S --out $W/S/images/.."
hostile out_in_images         'err:lies inside'        "$tr --data $W/S --out $W/S/images"
hostile out_in_images_new     'err:lies inside'        "$tr --data $W/S --out $W/S/images/new"
hostile out_in_sparse         'err:lies inside'        "$tr --data $W/S --out $W/S/sparse"
hostile out_in_sparse0        'err:lies inside'        "$tr --data $W/S --out $W/S/sparse/0"
hostile out_in_masks_dir      'err:lies inside'        "$tr --data $W/S --out $W/S/distractor_masks/x"
hostile out_contains_data     'err:contains'           "$tr --data $W/S --out $W"
hostile out_root              'err:filesystem root'    "$tr --data $W/S --out /"
hostile out_root_dotdot       'err:filesystem root'    "$tr --data $W/S --out /../.."
hostile out_empty             'err:--out is empty'     "$tr --data $W/S --out ''"
hostile out_is_file           'err:is a file'          "$tr --data $W/S --out $W/a_file"
hostile out_symlink_to_data   'err:same folder'        "$tr --data $W/S --out $W/link_to_S"
hostile out_via_symlink_in    'err:lies inside'        "$tr --data $W/S --out $W/link_to_S/images"
hostile data_via_symlink      'err:same folder'        "$tr --data $W/link_to_S --out $W/S"
hostile out_relative_data     'err:same folder'        "cd $W && $tr --data S --out ./S"
hostile out_is_masks          'err:same folder'        "$tr --data $W/S --masks $W/black_masks --out $W/black_masks"
hostile out_in_masks          'err:lies inside'        "$tr --data $W/S --masks $W/black_masks --out $W/black_masks/o"
hostile out_images_sfm        'err:same folder'        "$tr --images $W/S/images --out $W/S/images"
hostile out_sibling_prefix    'ok'                     "$tr --data $W/S --out $W/S_out"
hostile render_out_is_model   'err:same folder'        "$R --model $W/M --out $W/M"
hostile render_out_is_data    'err:same folder'        "$R --model $W/M --out $W/S"
hostile render_out_in_data    'err:lies inside'        "$R --model $W/M --out $W/S/images"
hostile render_out_root       'err:filesystem root'    "$R --model $W/M --out /"
hostile render_out_empty      'err:--out is empty'     "$R --model $W/M --out ''"
hostile render_out_file       'err:is a file'          "$R --model $W/M --out $W/a_file"
hostile render_out_contains   'err:contains'           "$R --model $W/M --out $W"
hostile render_in_model_ok    'ok'                     "$R --model $W/M --out $W/M/renders_again"
hostile synth_out_root        'err:filesystem root'    "$Y --scene $src/data/synthetic/tiny_clean.json --out / -q"
hostile synth_out_empty       'err:--out is empty'     "$Y --scene $src/data/synthetic/tiny_clean.json --out '' -q"
hostile synth_out_file        'err:is a file'          "$Y --scene $src/data/synthetic/tiny_clean.json --out $W/a_file -q"
hostile synth_out_holds_scene 'err:contains'           "cp $src/data/synthetic/tiny_clean.json $W/empty_dir/ && $Y --scene $W/empty_dir/tiny_clean.json --out $W/empty_dir -q"
hostile occlude_out_is_data   'err:same folder|inside' "$O --data $W/S --out $W/S"
hostile occlude_out_in_data   'err:inside'             "$O --data $W/S --out $W/S/images/o"
hostile occlude_out_root      'err:filesystem root'    "$O --data $W/S --out /"
hostile occlude_out_empty     'err:empty'              "$O --data $W/S --out ''"
hostile occlude_out_file      'err:is a file|not a folder' "$O --data $W/S --out $W/a_file"
hostile sfm_out_is_images     'err:inside|same folder' "$F --images $W/S/images --out $W/S/images -q"
hostile sfm_out_root          'err:filesystem root'    "$F --images $W/S/images --out / -q"
hostile sfm_out_empty         'err:empty'              "$F --images $W/S/images --out '' -q"
hostile sfm_out_file          'err:is a file'          "$F --images $W/S/images --out $W/a_file -q"
hostile sfm_out_contains      'err:contains'           "$F --images $W/S/images --out $W/S -q"
printf '{"scenes": ["%s"], "steps": 2, "eval_every": 1, "runs": [{"name": "a", "config": {"num_downscales": 0}}]}' "$W/S" >"$W/grid.json"
hostile bench_out_is_scene    'err:same folder'        "$B --grid $W/grid.json --out $W/S"
hostile bench_out_in_scene    'err:lies inside'        "$B --grid $W/grid.json --out $W/S/bench"
hostile bench_out_root        'err:filesystem root'    "$B --grid $W/grid.json --out /"
hostile bench_out_empty       'err:--out is empty'     "$B --grid $W/grid.json --out ''"
hostile bench_out_file        'err:is a file'          "$B --grid $W/grid.json --out $W/a_file"

# ---- JSON nested past the stack, everywhere JSON is read -------------------------------------
deep 300 >"$W/deep300.json"; deep 50000 >"$W/deep50k.json"; deep 200000 >"$W/deep200k.json"
deep_list 100000 >"$W/deeplist.json"
for d in deep300 deep50k deep200k deeplist; do
  hostile "config_file_$d"    'err:nested deeper than 256' "$tr --data $W/S --out $W/o_cfg_$d --config $W/$d.json"
  hostile "synth_scene_$d"    'err:nested deeper than 256' "$Y --scene $W/$d.json --out $W/o_syn_$d -q"
  hostile "bench_grid_$d"     'err:nested deeper than 256' "$B --grid $W/$d.json --out $W/o_bench_$d"
  hostile "resume_config_$d"  'err:nested deeper than 256' "rm -rf $W/o_res_$d && cp -r $W/M $W/o_res_$d && cp $W/$d.json $W/o_res_$d/config.json && $tr --data $W/S --out $W/o_res_$d --resume"
  hostile "render_config_$d"  'err:nested deeper than 256' "rm -rf $W/o_ren_$d && cp -r $W/M $W/o_ren_$d && cp $W/$d.json $W/o_ren_$d/config.json && $R --model $W/o_ren_$d --out $W/o_ren_${d}_out"
done
deep 10000 >"$W/deep10k.json"
hostile config_text_deep      'err:nested deeper than 256' "$tr --data $W/S --out $W/o_cfgtext --config \"\$(cat $W/deep10k.json)\""
hostile ckpt_metadata_deep    'err:nested deeper than 256' "rm -rf $W/o_ckdeep && cp -r $W/M $W/o_ckdeep && python3 $tools/edit_checkpoint.py $W/o_ckdeep/checkpoint.ckpt 'x=[]
for i in range(300): x=[x]
meta[\"junk\"]=x' && $tr --data $W/S --out $W/o_ckdeep --resume"
hostile config_depth_200_ok   'err:unknown setting'    "$tr --data $W/S --out $W/o_cfg200 --config \"\$(python3 -c \"print('{\\\"a\\\":'*200+'1'+'}'*200)\")\""

# ---- Checkpoints that do not fit the run ------------------------------------------------------
res() { echo "$T --data $W/$2 --out $1 --resume --iterations 6 --threads 2 --eval-every 0"; }
hostile ckpt_other_split      'err:another scene or split' "$(res "$(swapped split M MA)" S)"
hostile ckpt_other_split_rev  'err:another scene or split' "$(res "$(swapped split2 MA M)" S) --split all-train"
hostile ckpt_other_scene_static 'err:another scene or split' "$(res "$(swapped scene M MC)" S)"
hostile ckpt_other_scene_desplat 'err:another scene or split' "$(res "$(swapped scene2 M MCD)" S)"
hostile ckpt_other_scene_into_c 'err:another scene or split' "$(res "$(swapped scene3 MC M)" C)"
for v in 99 -1 -2147483648 100000; do
  hostile "ckpt_view_order_$v" "err:trainer/view_order.*$v" "$(res "$(ckpt vo_$v M "o=i32('trainer/view_order'); o[0]=$v; set_i32('trainer/view_order', o)")" S)"
done
hostile ckpt_view_order_short 'err:trainer/view_order' "$(res "$(ckpt vo_short M "arrays['trainer/view_order'][1]=[2]; set_i32('trainer/view_order',[0,1])")" S)"
hostile ckpt_view_order_dup   'err:not a permutation'  "$(res "$(ckpt vo_dup M "o=i32('trainer/view_order'); o[1]=o[0]; set_i32('trainer/view_order', o)")" S)"
for v in -1 -5 1000 '10**18' '"x"' '1.5' 'None'; do
  hostile "ckpt_view_pos_$v" "err:view_order_pos" "$(res "$(ckpt vp_$n M "meta['view_order_pos']=$v")" S)"
done
for v in -5 '10**18' '2**63' '-2**63' '"5"' '2.5' 'True' 'None' '[]'; do
  hostile "ckpt_step_$v" "err:field 'step'" "$(res "$(ckpt st_$n M "meta['step']=$v")" S)"
done
hostile ckpt_step_missing     "err:no field 'step'"    "$(res "$(ckpt st_missing M "del meta['step']")" S)"
hostile ckpt_adam_missing     "err:no field 'adam_step'" "$(res "$(ckpt ad_missing M "del meta['adam_step']")" S)"
hostile ckpt_adam_negative    "err:'adam_step' is -1"  "$(res "$(ckpt ad_neg M "meta['adam_step']=-1")" S)"
hostile ckpt_adam_past_step   "err:'adam_step'"        "$(res "$(ckpt ad_past M "meta['adam_step']=10**9")" S)"
hostile ckpt_rng_missing      "err:'rng'"              "$(res "$(ckpt rng_missing M "del meta['rng']")" S)"
hostile ckpt_rng_garbage      "err:RNG state"          "$(res "$(ckpt rng_bad M "meta['rng']='1 2 3'")" S)"
hostile ckpt_rng_number       "err:'rng'"              "$(res "$(ckpt rng_num M "meta['rng']=7")" S)"
hostile ckpt_stats_empty_bad  "err:statistics_empty"   "$(res "$(ckpt se_bad M "meta['statistics_empty']='yes'")" S)"
hostile ckpt_dist_adam_short  "err:distractors.adam_step" "$(res "$(ckpt da_short M "meta['distractors']['adam_step']=[1]")" S)"
hostile ckpt_dist_adam_neg    "err:distractors.adam_step" "$(res "$(ckpt da_neg M "meta['distractors']['adam_step'][0]=-4")" S)"
hostile ckpt_dist_views_bad   "err:distractors.views"  "$(res "$(ckpt dv_bad M "meta['distractors']['views']=5")" S)"
hostile ckpt_dist_views_num   "err:distractors.views"  "$(res "$(ckpt dv_num M "meta['distractors']['views'][0]=5")" S)"
hostile ckpt_dist_views_wrong "err:another scene|belongs to view" "$(res "$(ckpt dv_wrong M "meta['distractors']['views'][0]='nope.png'")" S)"
hostile ckpt_sh_degree_bad    "err:'sh_degree' is 7"          "$(res "$(ckpt sh_bad M "meta['sh_degree']=7")" S)"
for arr in static/opacity_logits static/means static/log_scales static/quats static/colors static/adam_m/means distractor/0/means distractor/0/opacity_logits; do
  for val in nan inf; do
    hostile "ckpt_${val}_${arr//\//_}" "err:array '$arr'.*not finite" "$(res "$(ckpt nf_$n M "v=f32('$arr'); v=[$val]*len(v); set_f32('$arr', v)")" S)"
  done
done
hostile ckpt_adam_v_negative  "err:adam_v/means.*negative" "$(res "$(ckpt av_neg M "v=f32('static/adam_v/means'); v[0]=-1.0; set_f32('static/adam_v/means', v)")" S)"
hostile ckpt_visible_negative "err:visible_count"      "$(res "$(ckpt vc_neg M "v=i32('static/stats/visible_count'); v[0]=-3; set_i32('static/stats/visible_count', v)")" S)"
hostile ckpt_seed_due_bad     "err:view_seed_due"      "$(res "$(ckpt sd_bad M "v=i32('trainer/view_seed_due'); v[0]=9; set_i32('trainer/view_seed_due', v)")" S)"
hostile ckpt_unexplained_nan  "err:view_static_unexplained" "$(res "$(ckpt un_nan M "v=f32('trainer/view_static_unexplained'); v[0]=nan; set_f32('trainer/view_static_unexplained', v)")" S)"
hostile ckpt_opacity_scalar   "err:opacity_logits"     "$(res "$(ckpt op_scalar M "arrays['static/opacity_logits'][1]=[]; arrays['static/opacity_logits'][2]=arrays['static/opacity_logits'][2][:4]")" S)"
hostile ckpt_means_short      "err:static/means"       "$(res "$(ckpt me_short M "arrays['static/means'][1]=[1,3]; arrays['static/means'][2]=arrays['static/means'][2][:12]")" S)"
hostile ckpt_no_scene_record  "ok:records no scene"    "$(res "$(ckpt no_scene M "del meta['scene']")" S)"
hostile ckpt_scene_renamed    "err:another scene or split" "$(res "$(ckpt sc_renamed M "meta['scene']['train'][0][0]='other.png'")" S)"
hostile ckpt_scene_resized    "err:another scene or split" "$(res "$(ckpt sc_resized M "meta['scene']['train'][0][1]=9999")" S)"
hostile ckpt_scene_garbage    "err:another scene or split|unreadable" "$(res "$(ckpt sc_garbage M "meta['scene']={'train': 5}")" S)"
swapped ns M MA >/dev/null && python3 "$tools/edit_checkpoint.py" "$W/s_ns/checkpoint.ckpt" "del meta['scene']"
hostile ckpt_no_scene_other_split 'err:trainer/view_order|distractors for' "$(res $W/s_ns S)"
hostile ckpt_truncated        'err:checkpoint'         "rm -rf $W/k_trunc && cp -r $W/M $W/k_trunc && truncate -s 100 $W/k_trunc/checkpoint.ckpt && $(res $W/k_trunc S)"
hostile ckpt_empty_file       'err:checkpoint'         "rm -rf $W/k_empty && cp -r $W/M $W/k_empty && : >$W/k_empty/checkpoint.ckpt && $(res $W/k_empty S)"
hostile ckpt_random_bytes     'err:checkpoint'         "rm -rf $W/k_rand && cp -r $W/M $W/k_rand && head -c 5000 /dev/urandom >$W/k_rand/checkpoint.ckpt && $(res $W/k_rand S)"
hostile ckpt_intact_resumes   'ok:resumed from'        "$(res "$(ckpt intact M "pass")" S)"
hostile render_ckpt_nan       "err:not finite"         "$R --model $(ckpt rnan M "v=f32('static/means'); v[0]=nan; set_f32('static/means', v)") --out $W/o_rnan"

# ---- Scenes: cameras, poses, names, masks -----------------------------------------------------
for f in 0 -1 -500 nan inf 1e-300; do
  hostile "fx_$f" 'err:camera 1.*(focal length|finite|param 0)' "$tr --data $(variant fx_$n "cameras[0][4]='$f'") --out $W/o_fx_$n"
done
hostile fy_zero 'err:camera 1.*focal length' "$tr --data $(variant fy0 "cameras[0][5]='0'") --out $W/o_fy0"
hostile cx_nan  'err:camera 1.*(finite|param 2)'       "$tr --data $(variant cxnan "cameras[0][6]='nan'") --out $W/o_cxnan"
for k in 1e6 -1e6 1e30 50; do
  hostile "k1_$k" 'err:camera 1.*distortion|cannot be undistorted|distortion coefficients' "$tr --data $(variant k1_$n "cameras[0][1]='OPENCV'; cameras[0] += ['$k','0','0','0']") --out $W/o_k1_$n"
done
hostile k1_small_ok 'ok'                     "$tr --data $(variant k1ok "cameras[0][1]='OPENCV'; cameras[0] += ['0.01','0','0','0']") --out $W/o_k1ok"
hostile poses_identical 'err:no baseline'    "$tr --data $(variant same "
for im in images: im[0][1:8] = images[0][0][1:8]") --out $W/o_same"
for s in 1e15 1e12 1e10; do
  hostile "translations_x$s" 'err:same units|sees any' "$tr --data $(variant tx_$n "
for im in images: im[0][5:8] = [repr(float(x)*$s) for x in im[0][5:8]]") --out $W/o_tx_$n"
done
hostile points_far_away 'err:sees any of the' "$tr --data $(variant far "
for p in points: p[2] = repr(float(p[2]) + 1e4)") --out $W/o_far"
hostile dup_name_dot   'err:name the same file' "$tr --data $(variant dup "images.append([[str(900)] + images[1][0][1:9] + ['./' + images[0][0][9]], ''])") --out $W/o_dup"
hostile dup_name_dir   'err:name the same file|leaves the image folder' "$tr --data $(variant dup2 "images.append([[str(901)] + images[1][0][1:9] + ['x/../' + images[0][0][9]], ''])") --out $W/o_dup2"
hostile dup_name_exact 'err:duplicate image name' "$tr --data $(variant dup3 "images.append([[str(902)] + images[1][0][1:9] + [images[0][0][9]], ''])") --out $W/o_dup3"
hostile name_latin1    'err:not UTF-8'          "$tr --data $(variant latin "images[0][0][9] = 'caf\xe9.png'") --out $W/o_latin"
hostile name_absolute  'err:name|relative'      "$tr --data $(variant abs "images[0][0][9] = '/etc/passwd'") --out $W/o_abs"
hostile name_dotdot    'err:name|\.\.'          "$tr --data $(variant dd "images[0][0][9] = '../x.png'") --out $W/o_dd"
hostile name_missing   'err:'                   "$tr --data $(variant miss "images[0][0][9] = 'missing.png'") --out $W/o_miss"
hostile camera_missing 'err:camera_id'          "$tr --data $(variant camid "images[0][0][8] = '77'") --out $W/o_camid"
hostile camera_width0  'err:width|size|camera'  "$tr --data $(variant w0 "cameras[0][2]='0'") --out $W/o_w0"
hostile no_images      'err:no registered images' "$tr --data $(variant noim "images.clear(); points.clear()") --out $W/o_noim"
hostile quat_zero      'err:qvec|quaternion|norm' "$tr --data $(variant q0 "images[0][0][1:5]=['0','0','0','0']") --out $W/o_q0"
hostile point_nan      'err:point3D|finite'     "$tr --data $(variant pnan "points[0][1]='nan'") --out $W/o_pnan"
mkdir -p "$W/black_masks"
for f in "$W"/S/images/*; do
  python3 -c "import sys,zlib,struct
w,h=64,48
raw=b''.join(b'\\x00'+b'\\x00'*w for _ in range(h))
def chunk(t,d): return struct.pack('>I',len(d))+t+d+struct.pack('>I',zlib.crc32(t+d))
open(sys.argv[1],'wb').write(b'\\x89PNG\\r\\n\\x1a\\n'+chunk(b'IHDR',struct.pack('>IIBBBBB',w,h,8,0,0,0,0))+chunk(b'IDAT',zlib.compress(raw))+chunk(b'IEND',b''))" "$W/black_masks/$(basename "${f%.*}").png"
done
hostile masks_all_black 'err:keeps no pixel|mask' "$tr --data $W/S --masks $W/black_masks --out $W/o_black"
hostile masks_missing_dir 'err:masks'           "$tr --data $W/S --masks $W/nope --out $W/o_nomask"
hostile masks_empty_dir 'err:holds no mask'     "$tr --data $W/S --masks $W/empty_dir --out $W/o_emptymask"

# ---- Options: counts, sizes, lists ---------------------------------------------------------------
for k in 10000000 1000000 100000 5000; do
  hostile "distractors_per_view_$k" 'err:more than a .* training view has pixels|GB' "$T --data $W/S --out $W/o_dpv_$k --iterations 2 --threads 2 --effects distractors --distractors-per-view $k"
done
hostile distractors_per_view_ok 'ok'            "$T --data $W/S --out $W/o_dpv_ok --iterations 2 --threads 2 --effects distractors --distractors-per-view 100"
for k in -1 abc 1e3 99999999999 ''; do
  hostile "distractors_per_view_bad_$k" 'err:distractors-per-view' "$T --data $W/S --out $W/o_dpvb_$n --iterations 2 --distractors-per-view '$k'"
done
for d in 0 -1 abc 1.5 100000; do
  hostile "downscale_$d" 'err:downscale' "$tr --data $W/S --out $W/o_ds_$n --downscale '$d'"
done
for t in -1 abc 99999; do
  hostile "threads_$t" 'err:threads' "$T --data $W/S --out $W/o_th_$n --iterations 2 --threads '$t'"
done
for s in nonsense 'every:0' 'every:-3' 'every:abc' 'list:' 'list:nope.png'; do
  hostile "split_$s" 'err:split' "$tr --data $W/S --out $W/o_split_$n --split '$s'"
done
hostile data_missing     'err:--data|scene|not exist|does not exist' "$tr --data $W/nope --out $W/o_dm"
hostile data_is_file     'err:--data|scene|not a dir|Directory' "$tr --data $W/a_file --out $W/o_df"
hostile data_no_sparse   'err:missing images/|sparse'           "$tr --data $W/empty_dir --out $W/o_dns"
hostile data_and_images  'err:--data|--images'  "$tr --data $W/S --images $W/S/images --out $W/o_di"
hostile config_missing_file 'err:config'        "$tr --data $W/S --out $W/o_cmf --config $W/nope.json"
hostile config_not_json  'err:not valid JSON'   "$tr --data $W/S --out $W/o_cnj --config '{nope'"
hostile config_unknown   "err:unknown setting"  "$tr --data $W/S --out $W/o_cu --config '{\"nope\": 1}'"
hostile config_wrong_type 'err:config|must|number' "$tr --data $W/S --out $W/o_cwt --config '{\"sh_degree\": \"x\"}'"
hostile effects_unknown  'err:effects'          "$T $train_fast --data $W/S --out $W/o_eu --effects bogus"
hostile preset_unknown   'err:preset'           "$tr --data $W/S --out $W/o_pu --preset bogus"
hostile static_and_effects 'err:contradict'     "$T $train_fast --data $W/S --out $W/o_se --static-only --effects distractors"
hostile resume_no_ckpt   'err:no checkpoint'    "$tr --data $W/S --out $W/empty_dir --resume"
hostile resume_overwrite 'err:contradict'       "$tr --data $W/S --out $W/M --resume --overwrite"
hostile rerun_no_overwrite 'err:already holds'  "$tr --data $W/S --out $W/M"
hostile render_views_empty 'err:selects no view' "$R --model $W/M --out $W/o_rv_empty --views ''"
hostile render_views_comma 'err:no view named|selects no view' "$R --model $W/M --out $W/o_rv_comma --views ','"
hostile render_views_unknown 'err:no view named' "$R --model $W/M --out $W/o_rv_unknown --views nope.png"
hostile render_views_test_none 'err:selects no view' "$R --model $W/MA --out $W/o_rv_none --views test"
hostile render_layer_bad 'err:unknown layer'    "$R --model $W/M --out $W/o_rl --layer bogus"
hostile render_static_model_distractor 'err:DeSplat model' "$R --model $W/MC --out $W/o_rsd --layer distractor --views train"
hostile render_appearance_none 'err:appearance' "$R --model $W/M --out $W/o_ra --appearance nope.png"
hostile render_model_empty 'err:config|checkpoint|model' "$R --model $W/empty_dir --out $W/o_rme"
hostile render_ok        'ok:wrote [1-9]'       "$R --model $W/M --out $W/o_rok --views test"

# ---- desplat_synth and desplat_bench inputs -------------------------------------------------------
echo '[1,2,3]' >"$W/array.json"; echo '{' >"$W/broken.json"; : >"$W/empty.json"; echo '{}' >"$W/object.json"
printf '\xff\xfe{}' >"$W/binary.json"
for f in array broken empty binary; do
  hostile "synth_scene_$f" 'err:scene description|JSON|object' "$Y --scene $W/$f.json --out $W/o_ys_$f -q"
  hostile "bench_grid_$f"  'err:grid|JSON|object' "$B --grid $W/$f.json --out $W/o_bg_$f"
done
hostile synth_scene_missing 'err:cannot read|not exist|Scene' "$Y --scene $W/nope.json --out $W/o_ysm -q"
hostile synth_scene_unknown_key 'err:unknown' "$Y --scene <(echo '{\"nope\": 1}') --out $W/o_ysu -q"
for patch in '{"camera": {"width": -5}}' '{"camera": {"width": 1e9}}' '{"views": {"count": 0}}' '{"views": {"count": -3}}' '{"views": {"count": 1e12}}' '{"camera": {"fov_degrees": 0}}' '{"camera": {"fov_degrees": 200}}' '{"seed": -1}' '{"seed": "x"}' '{"base": "nope.json"}'; do
  printf '%s' "$patch" | python3 -c "import json,sys; d=json.load(open('$src/data/synthetic/tiny_clean.json')); p=json.load(sys.stdin)
def merge(a,b):
  for k,v in b.items():
    if isinstance(v,dict) and isinstance(a.get(k),dict): merge(a[k],v)
    else: a[k]=v
merge(d,p); json.dump(d,open('$W/synth_$n.json','w'))"
  hostile "synth_patch_$patch" 'err:' "$Y --scene $W/synth_$n.json --out $W/o_yp_$n -q"
done
for g in '{"runs": 5}' '{"scenes": ["S"], "runs": 5}' '{"scenes": ["S"], "runs": [5]}' '{"scenes": "S", "runs": [{"name": "a"}]}' '{"scenes": [], "runs": [{"name": "a"}]}' '{"scenes": ["S"], "runs": []}' '{"scenes": ["S"], "steps": -1, "runs": [{"name": "a"}]}' '{"scenes": ["S"], "steps": "x", "runs": [{"name": "a"}]}' '{"scenes": ["S"], "runs": [{"name": "a"}, {"name": "a"}]}' '{"scenes": ["S"], "runs": [{"name": ""}]}' '{"scenes": ["S"], "runs": [{"name": "a", "bogus": 1}]}' '{"scenes": ["S"], "runs": [{"name": "a", "config": {"nope": 1}}]}' '{"scenes": ["S"], "runs": [{"name": "a", "downscale": 0}]}' '{"scenes": ["S"], "score_at": "x", "runs": [{"name": "a"}]}' '{"scenes": [5], "runs": [{"name": "a"}]}' '{"bogus": 1}'; do
  printf '%s' "$g" >"$W/grid_$n.json"
  hostile "bench_grid_$g" 'err:grid_[0-9]+\.json: .*(must|no scenes|no runs|two runs|without a name|unknown|wrong type|downscale|score_at|≥)' "$B --grid $W/grid_$n.json --out $W/o_bgg_$n"
done
hostile bench_scene_missing 'err:nope|scene|not exist' "printf '{\"scenes\": [\"nope\"], \"steps\": 2, \"runs\": [{\"name\": \"a\"}]}' >$W/grid_missing.json && $B --grid $W/grid_missing.json --out $W/o_bsm"
hostile sfm_images_missing 'err:images|not exist' "$F --images $W/nope --out $W/o_sfm_missing -q"
hostile sfm_images_empty   'err:no photos|photos|images' "$F --images $W/empty_dir --out $W/o_sfm_empty -q"
hostile occlude_data_missing 'err:data|sparse|not exist|scene' "$O --data $W/nope --out $W/o_occ_missing"
hostile occlude_fraction_bad 'err:fraction' "$O --data $W/S --out $W/o_occ_frac --fraction 2"

echo "== $n cases: clear ${count[clear]}, sensible ${count[sensible]}, crash ${count[crash]}, hang ${count[hang]}, silent ${count[silent]}, poor ${count[poor]}"
[ "${count[crash]}" -eq 0 ] && [ "${count[hang]}" -eq 0 ] && [ "${count[silent]}" -eq 0 ]
