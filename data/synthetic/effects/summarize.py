#!/usr/bin/python3
"""The effect benchmark (docs/BENCHMARKS.md): one row per (scene, effect set) run of run_bench.sh.

usage: summarize.py RUNS_DIR OUT_PREFIX
Writes OUT_PREFIX.csv, OUT_PREFIX.md (a markdown table) and OUT_PREFIX.png (test PSNR and
training time per scene and effect set). Needs python3-pil.
Sets: none, d, a, b, da, db, ab, dab (d distractors, a appearance, b background), and auto.
Auto's row is the run of the set its 1-step decision run (<scene>_autodecision) chose, with
the probe's seconds added to the training time: the probe trains its own model and the run
after it is the one `--effects` naming the chosen set trains (docs/METHOD.md §10).
Test PSNR/SSIM are the right halves of the test views for every set, so that sets with and
without appearance score the same pixels (with appearance or background, each test view's
embedding is first fitted on the left half: the Photo Tourism protocol, docs/METHOD.md §10).
"""
import csv, json, os, re, sys
from PIL import Image, ImageDraw

SCENES = ['none', 't', 'e', 's', 'te', 'ts', 'es', 'tes']
SETS = ['none', 'd', 'a', 'b', 'da', 'db', 'ab', 'dab']
NAMES = {'d': 'distractors', 'a': 'appearance', 'b': 'background'}


def effects_of(code):
    return ','.join(NAMES[c] for c in code if c in NAMES) or 'none'


def code_of(effects):
    return ''.join(k for k, v in NAMES.items() if v in effects.split(',')) or 'none'


def true_code(scene):
    """The simulated set of a scene named by its effects: t transients, e exposure, s sky."""
    if scene == 'none':
        return 'none'
    return ''.join(c for c, effect in (('d', 't'), ('a', 'e'), ('b', 's')) if effect in scene)


def read_run(runs, scene, code):
    d = os.path.join(runs, '%s_%s' % (scene, code))
    if not os.path.exists(os.path.join(d, 'metrics.json')):
        return None
    m = json.load(open(os.path.join(d, 'metrics.json')))
    chosen = m['effects']['chosen']
    if code_of(chosen) != code:
        sys.exit('%s trained effects %s, not %s' % (d, chosen, effects_of(code)))
    log = open(d + '.log').read()
    rss = re.search(r'Maximum resident set size \(kbytes\): (\d+)', log)
    step = m['median_step_seconds_full_resolution']
    return {'scene': scene, 'set': code, 'effects': effects_of(code), 'true_effects': effects_of(true_code(scene)),
            'psnr_right_half': round(m['mean_psnr_right_half'], 2), 'ssim_right_half': round(m['mean_ssim_right_half'], 4),
            'train_seconds': round(m['wall_seconds_this_run'], 1), 'probe_seconds': '',
            'step_ms': round(1000 * step['total'], 2), 'max_rss_mb': round(int(rss.group(1)) / 1024, 0) if rss else '',
            'static_gaussians': m['gaussians'],
            'distractor_gaussians': m['cost']['distractor_gaussians'] if 'cost' in m else 0}


def auto_row(runs, scene, rows):
    d = os.path.join(runs, '%s_autodecision' % scene)
    if not os.path.exists(os.path.join(d, 'metrics.json')):
        return None
    m = json.load(open(os.path.join(d, 'metrics.json')))
    code = code_of(m['effects']['chosen'])
    probe = m['effects'].get('evidence', {}).get('transients', {}).get('probe_seconds', 0.0)
    base = next((r for r in rows if r['scene'] == scene and r['set'] == code), None)
    if base is None:
        return None
    return dict(base, set='auto', probe_seconds=round(probe, 1), train_seconds=round(base['train_seconds'] + probe, 1))


def main(runs, prefix):
    rows = [r for s in SCENES for c in SETS for r in [read_run(runs, s, c)] if r]
    rows += [r for s in SCENES for r in [auto_row(runs, s, rows)] if r]
    order = SETS + ['auto']
    rows.sort(key=lambda r: (SCENES.index(r['scene']), order.index(r['set'])))
    with open(prefix + '.csv', 'w', newline='') as f:
        w = csv.DictWriter(f, fieldnames=list(rows[0].keys()))
        w.writeheader()
        w.writerows(rows)
    with open(prefix + '.md', 'w') as f:
        f.write('| scene | set | effects | PSNR (right half) | SSIM | train s | step ms | max RSS MB | static | distractor |\n')
        f.write('|---|---|---|---|---|---|---|---|---|---|\n')
        for r in rows:
            label = r['set'] + (' (the simulated set)' if r['set'] == true_code(r['scene']) else '')
            f.write('| %s | %s | %s | %.2f | %.4f | %.0f%s | %.1f | %s | %s | %s |\n' % (
                r['scene'], label, r['effects'], r['psnr_right_half'], r['ssim_right_half'], r['train_seconds'],
                ' (probe %.0f)' % r['probe_seconds'] if r['probe_seconds'] != '' else '', r['step_ms'], r['max_rss_mb'],
                format(r['static_gaussians'], ','), format(r['distractor_gaussians'], ',')))
        f.write('\n| scene | simulated | auto chose | auto PSNR | best manual set | its PSNR | auto − best |\n')
        f.write('|---|---|---|---|---|---|---|\n')
        for s in SCENES:
            auto = next((r for r in rows if r['scene'] == s and r['set'] == 'auto'), None)
            manual = [r for r in rows if r['scene'] == s and r['set'] != 'auto']
            if not auto or not manual:
                continue
            best = max(manual, key=lambda r: r['psnr_right_half'])
            f.write('| %s | %s | %s | %.2f | %s | %.2f | %+.2f |\n' % (
                s, effects_of(true_code(s)), auto['effects'], auto['psnr_right_half'], best['effects'],
                best['psnr_right_half'], auto['psnr_right_half'] - best['psnr_right_half']))
    plot(rows, prefix + '.png')


def plot(rows, path):
    sets = SETS + ['auto']
    colors = {'none': (150, 150, 150), 'd': (200, 60, 60), 'a': (230, 170, 40), 'b': (90, 170, 220),
              'da': (150, 90, 40), 'db': (140, 60, 170), 'ab': (60, 160, 80), 'dab': (40, 40, 40),
              'auto': (240, 120, 200)}
    bar, group = 11, 9 * 11 + 14
    left, top = 60, 40
    W, H = left + len(SCENES) * group + 20, 600
    img = Image.new('RGB', (W, H), 'white')
    g = ImageDraw.Draw(img)
    panels = [('test PSNR, right half (dB)', 'psnr_right_half', 10, 34), ('training time (s)', 'train_seconds', 0, None)]
    ph = (H - 2 * top - 40) // 2
    tmax = max(r['train_seconds'] for r in rows) * 1.1
    for k, (title, key, lo, hi) in enumerate(panels):
        hi = hi or tmax
        y0 = top + k * (ph + 40)
        g.text((left, y0 - 18), title, fill='black')
        g.line([(left, y0 + ph), (W - 10, y0 + ph)], fill='black')
        for t in range(5):
            v = lo + (hi - lo) * t / 4
            y = y0 + ph - ph * t / 4
            g.text((5, y - 6), '%.0f' % v, fill='black')
            g.line([(left - 4, y), (left, y)], fill='black')
        for i, scene in enumerate(SCENES):
            x0 = left + 8 + i * group
            g.text((x0 + 40, y0 + ph + 4), scene, fill='black')
            for j, s in enumerate(sets):
                r = next((r for r in rows if r['scene'] == scene and r['set'] == s), None)
                if not r:
                    continue
                h = max(0, min(1, (r[key] - lo) / (hi - lo))) * ph
                g.rectangle([x0 + j * bar, y0 + ph - h, x0 + j * bar + bar - 2, y0 + ph], fill=colors[s])
    for j, s in enumerate(sets):
        g.rectangle([left + j * 60, 8, left + 10 + j * 60, 18], fill=colors[s])
        g.text((left + 14 + j * 60, 7), s, fill='black')
    img.save(path)


if __name__ == '__main__':
    main(sys.argv[1], sys.argv[2])
