#!/usr/bin/env node
/*
 * scratch-bake TurboWarp harness: run projects in TurboWarp's real player (its compiler or its
 * interpreter, the WebGL renderer with the pen layer) in headless Chromium, and report what a
 * person pressing the green flag would get: how long until every script stopped, the stage image,
 * and every console or page error.
 *
 * Usage
 *   node vm/player.js PROJECT.sb3 [--mode compiled|interpreted|both] [--repeat N]
 *                     [--snapshots DIR] [--timeout MS] [--read-lists a,b] [--read-vars a,b]
 *   node vm/player.js --plan PLAN.json | --plan -
 *
 * Plan (JSON; paths relative to the plan file, or to the working directory for "-"):
 *   { "projects": [ {"file": "x.sb3", "id": "x"} ],     // id names the snapshots (default: file stem)
 *     "modes": ["compiled", "interpreted"],            // TurboWarp's compiler on / off
 *     "repeat": 1,                                     // runs per project and mode
 *     "interleave": false,                             // true: every page open at once, round k runs
 *                                                      //   each once (timings side by side)
 *     "action": {"greenFlag": true}                    // or {"call": {"target": "Mesh",
 *                                                      //   "proccode": "render", "args": []}}
 *     "snapshots": "DIR",                              // <id>-<mode>.png after the last run (optional)
 *     "read": {"target": "Mesh", "lists": [...], "variables": [...]},   // after the last run
 *     "timeoutMs": 120000,                             // per run
 *     "chromium": "/usr/bin/chromium" }                // default: $CHROMIUM, then chromium on PATH
 *
 * Output (JSON on stdout):
 *   { "versions": {"node", "@turbowarp/packager", "puppeteer-core", "chromium"},
 *     "results": [ { "id", "file", "mode",
 *         "runs": [ {"seconds":       green flag (or call) to the end of the step after which no
 *                                     script runs, wall clock in the page (performance.now()),
 *                    "stepSeconds":   the time inside those steps (sequencer only: no redraws,
 *                                     no waiting for the next frame),
 *                    "steps":         frames stepped, "done": false if it hit timeoutMs,
 *                    "running":       threads still running at the end (0 when done)} ],
 *         "snapshot": "DIR/<id>-<mode>.png" | null, "stage": [width, height] of the snapshot,
 *         "lists": {...}, "variables": {...},        // what "read" asked for
 *         "runtimeOptions": {...},                   // vm.runtime.runtimeOptions after the last run
 *         "errors": [ "console error: ...", "page error: ...", "request blocked: URL", ... ] } ] }
 * Exit status: 0; 3 if the harness itself failed (the JSON then has "error"); 2 on bad arguments.
 *
 * How (facts that hold for @turbowarp/packager 3.13.0):
 * - The .sb3 is packaged into one self-contained HTML page with the packager's Node API (its
 *   scaffolding ships inside the npm package, so no network). An .sb3 missing an asset would make
 *   the packager download it: such a file is refused before packaging and reported ("packaging:
 *   asset missing from the archive"), as is anything that is not a zip. In the page, cloud
 *   variables are local; every request that is not a file:, data: or blob: URL is blocked and
 *   reported as an error, and DNS resolves nothing.
 * - Debian's chromium runs headless with --use-angle=swiftshader --enable-unsafe-swiftshader (WebGL
 *   on the CPU), a 480x360 viewport at device scale 1, so the stage canvas has the stage's pixels.
 * - The page's frame loop is started (vm.start()) and the green flag pressed with vm.greenFlag();
 *   the run is over at the first AFTER_EXECUTE event after which no thread is running. TurboWarp
 *   removes finished threads one frame late (at the start of the next step), so a thread counts as
 *   running only while its status is not DONE.
 * - renderer.draw() does nothing when nothing changed; renderer.requestSnapshot marks the stage
 *   dirty and hands over the canvas at the next draw, pen layer included.
 */
'use strict';

const fs = require('fs');
const os = require('os');
const path = require('path');
const crypto = require('crypto');
const {execFileSync} = require('child_process');

const HERE = __dirname;

function readVersion (pkg) {
    try {
        return JSON.parse(fs.readFileSync(path.join(HERE, 'node_modules', pkg, 'package.json'), 'utf8')).version;
    } catch (e) {
        return null;
    }
}

function findChromium (given) {
    const cands = [given, process.env.CHROMIUM].filter(Boolean);
    for (const dir of (process.env.PATH || '').split(path.delimiter)) {
        for (const name of ['chromium', 'chromium-browser']) cands.push(path.join(dir, name));
    }
    for (const c of cands) {
        try {
            fs.accessSync(c, fs.constants.X_OK);
            return c;
        } catch (e) { /* next */ }
    }
    return null;
}

// ------------------------------------------------------------------ packaging
/* An .sb3 whose project.json names an asset the archive lacks would make the packager download it
 * from the asset server: refuse it here, so the harness never goes to the network. */
async function missingAssets (data) {
    const JSZip = require('@turbowarp/jszip');
    let zip;
    try {
        zip = await JSZip.loadAsync(data);
    } catch (e) {
        throw new Error('not an .sb3 (zip) archive');
    }
    const pj = zip.file('project.json');
    if (!pj) throw new Error('no project.json in the archive');
    const project = JSON.parse(await pj.async('string'));
    const names = new Set(Object.keys(zip.files).map(n => n.replace(/^.*\//, '')));
    const missing = [];
    for (const t of project.targets || []) {
        for (const a of [...(t.costumes || []), ...(t.sounds || [])]) {
            const name = a.md5ext || `${a.assetId}.${a.dataFormat}`;
            if (!names.has(name)) missing.push(name);
        }
    }
    return missing;
}

async function packageProject (file, cacheDir) {
    const data = fs.readFileSync(file);
    const missing = await missingAssets(data);
    if (missing.length) throw new Error(`asset missing from the archive (not fetched): ${missing.join(', ')}`);
    const key = crypto.createHash('sha256').update(data).update(readVersion('@turbowarp/packager') || '')
        .digest('hex').slice(0, 24);
    const out = path.join(cacheDir, `${key}.html`);
    if (fs.existsSync(out)) return out;
    const Packager = require('@turbowarp/packager');
    const loaded = await Packager.loadProject(data);
    const p = new Packager.Packager();
    p.project = loaded;
    p.options.cloudVariables.mode = 'local';
    const res = await p.package();
    const tmp = `${out}.${process.pid}.tmp`;
    fs.writeFileSync(tmp, res.data);
    fs.renameSync(tmp, out);
    return out;
}

// ------------------------------------------------------------------ in the page
/* eslint-disable no-undef */
function pageLoaded () {
    const err = document.getElementById('error');
    if (err && !err.hidden) return 'error: ' + (document.getElementById('error-message') || {}).textContent;
    const loading = document.getElementById('loading');
    return Boolean(window.vm && window.vm.runtime.targets.length && (!loading || loading.hidden));
}

function pageSetup (compiled) {
    const vm = window.vm;
    vm.setCompilerOptions({enabled: compiled, warpTimer: false});
    const h = window.__bake = {steps: 0, stepMs: 0, t0: 0, tEnd: 0, active: false, done: false, s0: 0};
    const DONE = 4; // Thread.STATUS_DONE
    h.running = () => vm.runtime.threads.filter(t => !t.isKilled && t.status !== DONE && !t.updateMonitor).length;
    vm.runtime.on('BEFORE_EXECUTE', () => {
        h.s0 = performance.now();
    });
    vm.runtime.on('AFTER_EXECUTE', () => {
        if (!h.active) return;
        h.steps++;
        h.stepMs += performance.now() - h.s0;
        if (h.running() === 0) {
            h.active = false;
            h.done = true;
            h.tEnd = performance.now();
        }
    });
    vm.start();
    return true;
}

function pageStart (action) {
    const vm = window.vm;
    const h = window.__bake;
    h.steps = 0;
    h.stepMs = 0;
    h.done = false;
    h.t0 = performance.now();
    h.active = true;
    if (action.call) {
        const c = action.call;
        const target = c.target ? vm.runtime.targets.find(t => t.isOriginal && t.getName() === c.target) :
            vm.runtime.targets.find(t => !t.isStage && t.isOriginal);
        if (!target) throw new Error('no target ' + c.target);
        const info = target.blocks.getProcedureParamNamesIdsAndDefaults(c.proccode);
        if (!info) throw new Error('no custom block ' + c.proccode);
        const id = 'bake-call-' + Math.random().toString(36).slice(2);
        const inputs = {};
        info[1].forEach((aid, i) => {
            const sid = id + '-arg' + i;
            target.blocks.createBlock({id: sid, opcode: 'text', inputs: {},
                fields: {TEXT: {name: 'TEXT', value: String((c.args || [])[i])}},
                next: null, parent: id, shadow: true, topLevel: false});
            inputs[aid] = {name: aid, block: sid, shadow: sid};
        });
        target.blocks.createBlock({id, opcode: 'procedures_call', inputs, fields: {}, next: null, parent: null,
            shadow: false, topLevel: true, mutation: {tagName: 'mutation', children: [], proccode: c.proccode,
                argumentids: JSON.stringify(info[1]), warp: 'false'}});
        vm.runtime._pushThread(id, target);
    } else {
        vm.greenFlag();
    }
    return true;
}

function pageStatus () {
    const h = window.__bake;
    return {done: h.done, steps: h.steps, stepMs: h.stepMs, ms: (h.done ? h.tEnd : performance.now()) - h.t0,
        running: h.running()};
}

function pageSnapshot () {
    return new Promise(resolve => window.vm.renderer.requestSnapshot(url => resolve(url)));
}

function pageRead (read) {
    const vm = window.vm;
    const target = read.target ? vm.runtime.targets.find(t => t.isOriginal && t.getName() === read.target) :
        vm.runtime.targets.find(t => !t.isStage && t.isOriginal);
    const out = {lists: {}, variables: {}};
    for (const scope of [vm.runtime.getTargetForStage(), target].filter(Boolean)) {
        for (const v of Object.values(scope.variables)) {
            if (v.type === 'list' && (read.lists || []).includes(v.name)) out.lists[v.name] = v.value.slice();
            if (v.type === '' && (read.variables || []).includes(v.name)) out.variables[v.name] = v.value;
        }
    }
    return out;
}
/* eslint-enable no-undef */

// ------------------------------------------------------------------ driving
function sleep (ms) {
    return new Promise(r => setTimeout(r, ms));
}

async function waitFor (page, fn, timeoutMs, what, arg) {
    const t0 = Date.now();
    for (;;) {
        const v = await page.evaluate(fn, arg);
        if (typeof v === 'string') throw new Error(`${what}: ${v}`);
        if (v) return v;
        if (Date.now() - t0 > timeoutMs) throw new Error(`${what}: timed out after ${timeoutMs} ms`);
        await sleep(20);
    }
}

// a project in a mode: open (load, set up), run the action once, finish (read, snapshot, close)
async function openOne (browser, html, proj, mode, plan) {
    const res = {id: proj.id, file: proj.file, mode, runs: [], snapshot: null, stage: null, lists: {}, variables: {},
        errors: []};
    const one = {res, page: null, broken: false};
    try {
        const page = one.page = await browser.newPage();
        await page.setViewport({width: 480, height: 360, deviceScaleFactor: 1});
        page.on('console', msg => {
            if (msg.type() === 'error') res.errors.push(`console error: ${msg.text()}`);
        });
        page.on('pageerror', e => res.errors.push(`page error: ${e && e.message ? e.message : String(e)}`));
        await page.setRequestInterception(true);
        page.on('request', req => {
            const u = req.url();
            if (/^(file|data|blob):/.test(u)) req.continue();
            else {
                res.errors.push(`request blocked: ${u.slice(0, 200)}`);
                req.abort();
            }
        });
        const timeout = plan.timeoutMs || 120000;
        await page.goto('file://' + html, {waitUntil: 'load', timeout});
        await waitFor(page, pageLoaded, timeout, 'loading the project');
        await page.evaluate(pageSetup, mode === 'compiled');
        await sleep(100); // a few idle frames
    } catch (e) {
        res.errors.push(`harness: ${e && e.message ? e.message : String(e)}`);
        one.broken = true;
    }
    return one;
}

async function runOnce (one, plan) {
    if (one.broken) return;
    const res = one.res;
    try {
        const timeout = plan.timeoutMs || 120000;
        await one.page.bringToFront(); // a page in the background runs at a lower priority
        await sleep(40);
        await one.page.evaluate(pageStart, plan.action || {greenFlag: true});
        const t0 = Date.now();
        let st;
        for (;;) {
            st = await one.page.evaluate(pageStatus);
            if (st.done || Date.now() - t0 > timeout) break;
            await sleep(st.ms > 2000 ? 50 : 5);
        }
        res.runs.push({seconds: st.ms / 1000, stepSeconds: st.stepMs / 1000, steps: st.steps, done: st.done,
            running: st.running});
        if (!st.done) one.broken = true;
        await sleep(40);
    } catch (e) {
        res.errors.push(`harness: ${e && e.message ? e.message : String(e)}`);
        one.broken = true;
    }
}

async function finishOne (one, plan, baseDir) {
    const res = one.res;
    try {
        if (one.page && res.runs.length) {
            const page = one.page;
            await page.bringToFront(); // a hidden page does not draw: the snapshot would never come
            await sleep(40);
            if (plan.read) Object.assign(res, await page.evaluate(pageRead, plan.read));
            // the runtime options in force (the project's TurboWarp settings comment applied)
            res.runtimeOptions = await page.evaluate(() => Object.assign({}, window.vm.runtime.runtimeOptions));
            const url = await page.evaluate(pageSnapshot);
            const png = Buffer.from(url.slice(url.indexOf(',') + 1), 'base64');
            res.stage = [png.readUInt32BE(16), png.readUInt32BE(20)];
            if (plan.snapshots) {
                const dir = path.resolve(baseDir, plan.snapshots);
                fs.mkdirSync(dir, {recursive: true});
                const file = path.join(dir, `${res.id}-${res.mode}.png`);
                fs.writeFileSync(file, png);
                res.snapshot = file;
            }
        }
    } catch (e) {
        res.errors.push(`harness: ${e && e.message ? e.message : String(e)}`);
    } finally {
        if (one.page) await one.page.close();
    }
    return res;
}

async function main (plan, baseDir) {
    const out = {versions: {node: process.version, '@turbowarp/packager': readVersion('@turbowarp/packager'),
        'puppeteer-core': readVersion('puppeteer-core'), chromium: null}, results: []};
    const exe = findChromium(plan.chromium);
    if (!exe) throw new Error('chromium not found (install Debian\'s chromium or set CHROMIUM)');
    try {
        out.versions.chromium = execFileSync(exe, ['--version'], {encoding: 'utf8', timeout: 60000}).trim();
    } catch (e) { /* reported as null */ }
    const cacheDir = plan.cacheDir ? path.resolve(baseDir, plan.cacheDir) :
        fs.mkdtempSync(path.join(os.tmpdir(), 'bake-player-'));
    const projects = (plan.projects || []).map(p => {
        const file = path.resolve(baseDir, p.file);
        return {file, id: p.id || path.basename(file).replace(/\.[^.]*$/, '')};
    });
    const htmls = [];
    const refused = [];
    for (const p of projects) {
        try {
            htmls.push(await packageProject(p.file, cacheDir));
            refused.push(null);
        } catch (e) {
            htmls.push(null);
            refused.push(e && e.message ? e.message : String(e));
        }
    }
    const puppeteer = require('puppeteer-core');
    const browser = await puppeteer.launch({
        executablePath: exe, headless: true, userDataDir: path.join(cacheDir, 'profile'),
        args: ['--no-sandbox', '--use-angle=swiftshader', '--enable-unsafe-swiftshader', '--no-first-run',
            '--disable-background-networking', '--disable-component-update', '--disable-sync',
            '--disable-background-timer-throttling', '--disable-renderer-backgrounding',
            '--disable-backgrounding-occluded-windows', '--host-resolver-rules=MAP * ~NOTFOUND',
            '--window-size=480,360']
    });
    try {
        const jobs = [];
        for (let i = 0; i < projects.length; i++) {
            for (const mode of plan.modes || ['compiled', 'interpreted']) {
                if (mode !== 'compiled' && mode !== 'interpreted') throw new Error(`unknown mode ${mode}`);
                jobs.push({i, mode});
            }
        }
        const repeat = Math.max(1, plan.repeat || 1);
        const refusedResult = (i, mode) => ({id: projects[i].id, file: projects[i].file, mode, runs: [], snapshot: null,
            stage: null, lists: {}, variables: {}, errors: [`packaging: ${refused[i]}`]});
        if (plan.interleave) {
            // every page open at once; round k runs each once, so all see the same machine load
            const ones = [];
            for (const j of jobs) ones.push(refused[j.i] ? null : await openOne(browser, htmls[j.i], projects[j.i], j.mode, plan));
            for (let k = 0; k < repeat; k++) {
                for (const one of ones) if (one) await runOnce(one, plan);
            }
            for (let n = 0; n < jobs.length; n++) {
                out.results.push(ones[n] ? await finishOne(ones[n], plan, baseDir) : refusedResult(jobs[n].i, jobs[n].mode));
            }
        } else {
            for (const j of jobs) {
                if (refused[j.i]) {
                    out.results.push(refusedResult(j.i, j.mode));
                    continue;
                }
                const one = await openOne(browser, htmls[j.i], projects[j.i], j.mode, plan);
                for (let k = 0; k < repeat; k++) await runOnce(one, plan);
                out.results.push(await finishOne(one, plan, baseDir));
            }
        }
    } finally {
        await browser.close();
        if (!plan.cacheDir) fs.rmSync(cacheDir, {recursive: true, force: true});
    }
    return out;
}

function parseArgs (argv) {
    const plan = {projects: []};
    let baseDir = process.cwd();
    for (let i = 0; i < argv.length; i++) {
        const a = argv[i];
        const next = () => {
            if (i + 1 >= argv.length) throw new Error(`${a} needs a value`);
            return argv[++i];
        };
        if (a === '--plan') {
            const p = next();
            const text = p === '-' ? fs.readFileSync(0, 'utf8') : fs.readFileSync(p, 'utf8');
            if (p !== '-') baseDir = path.dirname(path.resolve(p));
            return {plan: JSON.parse(text), baseDir};
        } else if (a === '--mode') {
            const m = next();
            plan.modes = m === 'both' ? ['compiled', 'interpreted'] : [m];
        } else if (a === '--repeat') plan.repeat = parseInt(next(), 10);
        else if (a === '--snapshots') plan.snapshots = next();
        else if (a === '--timeout') plan.timeoutMs = parseInt(next(), 10);
        else if (a === '--read-lists') (plan.read = plan.read || {}).lists = next().split(',').filter(Boolean);
        else if (a === '--read-vars') (plan.read = plan.read || {}).variables = next().split(',').filter(Boolean);
        else if (a === '-h' || a === '--help') {
            process.stdout.write(fs.readFileSync(__filename, 'utf8').split('*/')[0]);
            process.exit(0);
        } else if (a.startsWith('--')) throw new Error(`unknown option ${a}`);
        else plan.projects.push({file: a});
    }
    if (!plan.projects.length) throw new Error('no project given (see --help)');
    return {plan, baseDir};
}

if (require.main === module) {
    let parsed;
    try {
        parsed = parseArgs(process.argv.slice(2));
    } catch (e) {
        process.stderr.write(`player.js: ${e.message}\n`);
        process.exit(2);
    }
    main(parsed.plan, parsed.baseDir).then(out => {
        process.stdout.write(JSON.stringify(out) + '\n');
    }, e => {
        process.stdout.write(JSON.stringify({error: (e && e.stack) ? e.stack : String(e), results: []}) + '\n');
        process.exitCode = 3;
    });
}

module.exports = {main, packageProject};
