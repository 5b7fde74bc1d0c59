#!/usr/bin/python3
"""Issue 15's effect benchmark: one row per (scene, effect set) run of run_bench.sh.

usage: summarize.py RUNS_DIR OUT_PREFIX
Writes OUT_PREFIX.csv, OUT_PREFIX.md (a markdown table) and OUT_PREFIX.png (test PSNR and
training time per scene and effect set). Needs python3-pil.
Test PSNR/SSIM are the right halves of the test views for every set, so that sets with and
without appearance score the same pixels (with appearance, each test view's embedding is
first fitted on the left half: the Photo Tourism protocol, docs/METHOD.md §10).
"""
import csv, json, os, re, sys
from PIL import Image, ImageDraw

SCENES = ['none', 't', 'e', 's', 'te', 'ts', 'es', 'tes']
SETS = ['none', 'true', 'auto', 'all']
TRUE = {'none': '', 't': 'distractors', 'e': 'appearance', 's': 'background', 'te': 'distractors,appearance',
        'ts': 'distractors,background', 'es': 'appearance,background', 'tes': 'distractors,appearance,background'}
ALL = 'distractors,appearance,background'


def chosen_of(m):
    return m['effects']['chosen'] if m['effects']['chosen'] != 'none' else ''


def main(runs, prefix):
    rows = []
    for scene in SCENES:
        for label in ['none', 'auto', 'true', 'all']:
            d = os.path.join(runs, '%s_%s' % (scene, label))
            if not os.path.exists(os.path.join(d, 'metrics.json')):
                continue
            m = json.load(open(os.path.join(d, 'metrics.json')))
            log = open(d + '.log').read()
            rss = re.search(r'Maximum resident set size \(kbytes\): (\d+)', log)
            step = m['median_step_seconds_full_resolution']
            rows.append({'scene': scene, 'set': label, 'effects': chosen_of(m) or 'none',
                         'true_effects': TRUE[scene] or 'none',
                         'psnr_right_half': round(m['mean_psnr_right_half'], 2),
                         'ssim_right_half': round(m['mean_ssim_right_half'], 4),
                         'train_seconds': round(m['wall_seconds_this_run'], 1),
                         'step_ms': round(1000 * step['total'], 2),
                         'max_rss_mb': round(int(rss.group(1)) / 1024, 0) if rss else '',
                         'static_gaussians': m['gaussians'],
                         'distractor_gaussians': m['cost']['distractor_gaussians'] if 'cost' in m else 0})
    # Runs with the same effects as another label of the scene stand for both.
    for scene in SCENES:
        have = {r['set']: r for r in rows if r['scene'] == scene}
        for label, effects in [('true', TRUE[scene] or 'none'), ('all', ALL)]:
            if label not in have:
                for r in have.values():
                    if r['effects'] == effects:
                        rows.append(dict(r, set=label))
                        break
    rows.sort(key=lambda r: (SCENES.index(r['scene']), SETS.index(r['set'])))
    keys = list(rows[0].keys())
    with open(prefix + '.csv', 'w', newline='') as f:
        w = csv.DictWriter(f, fieldnames=keys)
        w.writeheader()
        w.writerows(rows)
    with open(prefix + '.md', 'w') as f:
        f.write('| scene | set | effects | PSNR (right half) | SSIM | train s | step ms | max RSS MB | static | distractor |\n')
        f.write('|---|---|---|---|---|---|---|---|---|---|\n')
        for r in rows:
            f.write('| %s | %s | %s | %.2f | %.4f | %.0f | %.1f | %s | %s | %s |\n' % (
                r['scene'], r['set'], r['effects'], r['psnr_right_half'], r['ssim_right_half'], r['train_seconds'],
                r['step_ms'], r['max_rss_mb'], format(r['static_gaussians'], ','), format(r['distractor_gaussians'], ',')))
    plot(rows, prefix + '.png')


def plot(rows, path):
    colors = {'none': (150, 150, 150), 'true': (40, 120, 200), 'auto': (230, 120, 30), 'all': (60, 160, 80)}
    W, H, top, left, bar = 900, 560, 30, 60, 20
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
            x0 = left + 10 + i * 104
            g.text((x0 + 30, y0 + ph + 4), scene, fill='black')
            for j, s in enumerate(SETS):
                r = next((r for r in rows if r['scene'] == scene and r['set'] == s), None)
                if not r:
                    continue
                h = max(0, min(1, (r[key] - lo) / (hi - lo))) * ph
                g.rectangle([x0 + j * bar, y0 + ph - h, x0 + j * bar + bar - 3, y0 + ph], fill=colors[s])
    for j, s in enumerate(SETS):
        g.rectangle([W - 330 + j * 80, 8, W - 320 + j * 80, 18], fill=colors[s])
        g.text((W - 316 + j * 80, 7), s, fill='black')
    img.save(path)


if __name__ == '__main__':
    main(sys.argv[1], sys.argv[2])
