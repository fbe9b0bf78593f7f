#!/usr/bin/env node
/*
 * scratch-bake VM harness: load a project into the real Scratch VM (scratch-vm, headless, no
 * renderer), validate it with scratch-parser, run procedures or the green flag, and print the
 * lists, variables, executed-block counts and pen strokes as JSON on stdout.
 *
 * Usage
 *   node vm/run.js PROJECT [options]          PROJECT: .sb3 | .sprite3 | project.json
 *     --validate-only                        only run scratch-parser (exit 1 if invalid)
 *     --green-flag                           click the green flag and run until all scripts stop
 *     --call PROCCODE [--target NAME] [--args JSON-ARRAY]
 *                                            run one custom block (e.g. "bsp walk %s %s %s")
 *     --lists a,b  --vars a,b                what to print (default: every list and variable)
 *     --pen                                  record pen strokes
 *   node vm/run.js --plan PLAN.json | --plan -   (several runs in one process, see below)
 *
 * Plan (JSON):
 *   { "load": "x.sb3",                       // or "project": {...project.json...}
 *     "sprites": ["y.sprite3"],              // added with vm.addSprite after loading
 *     "validate": ["x.sb3", "y.sprite3"],    // files checked with scratch-parser (default: load + sprites)
 *     "runs": [ { "call": {"target": "Reader", "proccode": "...", "args": [...]},
 *                 "greenFlag": false, "pen": false, "opcodes": false,
 *                 "read": {"target": "Reader", "lists": [...], "variables": [...]} }, ... ] }
 *
 * Several plans in one process (a fresh VM each): {"jobs": [plan, ...]} -> {"jobs": [output, ...]}.
 *
 * Output (JSON): { "versions": {...}, "validation": [{file, ok, error}], "runs": [
 *   { "blocks": <blocks executed>, "byOpcode": {...}?, "steps": <VM steps>, "ms": <wall ms>,
 *     "done": true|false, "lists": {name: [...]}, "variables": {name: value}, "pen": [...]? } ] }
 *
 * "blocks" counts every non-shadow block the VM executes (each call of a block's primitive
 * function: a repeat loop counts once per iteration, a reporter once per evaluation, including
 * variable and argument reporters, a custom block call once plus its definition hat once). Pen strokes are recorded without a renderer by
 * listening to sprite moves while the pen is down: [x0, y0, x1, y1, diameter, r, g, b, a].
 *
 * Facts used (shared/docs/scratch.md section 5): runtime.currentStepTime is null until
 * vm.start(), so we set it and call runtime._step() ourselves; turbo mode keeps a step from
 * ending on a redraw request; warp threads yield after 500 ms, so we keep stepping.
 */
'use strict';

const fs = require('fs');
const path = require('path');

const HERE = __dirname;
const VirtualMachine = require('scratch-vm');
const parser = require('scratch-parser');
const {ScratchStorage} = require('scratch-storage');

function readVersion (pkg) {
    try {
        return JSON.parse(fs.readFileSync(path.join(HERE, 'node_modules', pkg, 'package.json'), 'utf8')).version;
    } catch (e) {
        return null;
    }
}

function quietLogs () {
    // minilog prints warnings (no renderer, missing translations) on stderr; keep stdout clean.
    try {
        const minilog = require('minilog');
        minilog.disable();
    } catch (e) { /* not fatal */ }
    const origWarn = console.warn;
    const origLog = console.log;
    console.warn = () => {};
    console.log = () => {};
    return {warn: origWarn, log: origLog};
}

function isSpriteFile (file, buf) {
    if (file.endsWith('.sprite3')) return true;
    if (file.endsWith('.json')) {
        try {
            const obj = JSON.parse(buf.toString('utf8'));
            return !obj.targets && 'isStage' in obj;
        } catch (e) {
            return false;
        }
    }
    return false;
}

function validate (buf, isSprite) {
    return new Promise(resolve => {
        parser(buf, isSprite, (err, res) => {
            if (err) {
                let error = err;
                if (typeof err !== 'string') {
                    try {
                        error = JSON.stringify(err);
                    } catch (e) {
                        error = String(err);
                    }
                }
                resolve({ok: false, error: error});
            } else {
                resolve({ok: true, projectVersion: res && res[0] && res[0].projectVersion});
            }
        });
    });
}

function makeVM (withStorage) {
    const vm = new VirtualMachine();
    // Storage is needed to load the assets inside an .sb3/.sprite3. A bare project.json has no
    // assets: with storage attached, the VM would try to fetch them, fail, and then crash on its
    // "missing costume" fallback, which needs a renderer. So bare JSON loads without storage.
    if (withStorage) vm.attachStorage(new ScratchStorage());
    vm.setTurboMode(true);
    vm.setCompatibilityMode(true);
    vm.runtime.currentStepTime = 1000 / 30;
    return vm;
}

// ------------------------------------------------------------------ block counting
function instrument (vm) {
    const rt = vm.runtime;
    const counter = {total: 0, byOpcode: null};
    for (const opcode of Object.keys(rt._primitives)) {
        const fn = rt._primitives[opcode];
        if (fn.__bakeCounted) continue;
        const wrapped = function () {
            counter.total++;
            if (counter.byOpcode) counter.byOpcode[opcode] = (counter.byOpcode[opcode] || 0) + 1;
            return fn.apply(this, arguments);
        };
        wrapped.__bakeCounted = true;
        rt._primitives[opcode] = wrapped;
    }
    return counter;
}

// ------------------------------------------------------------------ pen recording
function attachPenRecorder (vm, strokes) {
    const handler = (target, oldX, oldY, isForce) => {
        if (isForce || !strokes.on) return;
        const state = target.getCustomState('Scratch.pen');
        if (!state || !state.penDown) return;
        const a = state.penAttributes;
        strokes.list.push([oldX, oldY, target.x, target.y, a.diameter,
            Math.round(a.color4f[0] * 255), Math.round(a.color4f[1] * 255),
            Math.round(a.color4f[2] * 255), Math.round(a.color4f[3] * 255)]);
    };
    for (const t of vm.runtime.targets) {
        if (t.isStage || t.__bakePen) continue;
        t.addListener('TARGET_MOVED', handler);
        t.__bakePen = true;
    }
    // pen down draws a dot where the sprite is
    const prims = vm.runtime._primitives;
    const down = prims.pen_penDown;
    if (down && !down.__bakePen) {
        const wrapped = function (args, util) {
            const r = down.apply(this, arguments);
            if (strokes.on) {
                const t = util.target;
                const a = t.getCustomState('Scratch.pen').penAttributes;
                strokes.list.push([t.x, t.y, t.x, t.y, a.diameter,
                    Math.round(a.color4f[0] * 255), Math.round(a.color4f[1] * 255),
                    Math.round(a.color4f[2] * 255), Math.round(a.color4f[3] * 255)]);
            }
            return r;
        };
        wrapped.__bakePen = true;
        wrapped.__bakeCounted = down.__bakeCounted;
        prims.pen_penDown = wrapped;
    }
    const clear = prims.pen_clear;
    if (clear && !clear.__bakePen) {
        const wrapped = function () {
            if (strokes.on) strokes.list.length = 0;
            return clear.apply(this, arguments);
        };
        wrapped.__bakePen = true;
        wrapped.__bakeCounted = clear.__bakeCounted;
        prims.pen_clear = wrapped;
    }
}

// ------------------------------------------------------------------ running
let callSerial = 0;

function findTarget (vm, name) {
    if (name === undefined || name === null) return vm.runtime.targets.find(t => !t.isStage && t.isOriginal) ||
        vm.runtime.getTargetForStage();
    const t = vm.runtime.targets.find(x => x.isOriginal && x.getName() === name);
    if (!t) throw new Error(`no target named ${JSON.stringify(name)}`);
    return t;
}

function pushCall (vm, target, proccode, args) {
    const info = target.blocks.getProcedureParamNamesIdsAndDefaults(proccode);
    if (!info) throw new Error(`no custom block ${JSON.stringify(proccode)} in ${target.getName()}`);
    const argIds = info[1];
    args = args || [];
    if (args.length !== argIds.length) {
        throw new Error(`${proccode}: expected ${argIds.length} arguments, got ${args.length}`);
    }
    const id = `bake-call-${++callSerial}`;
    const inputs = {};
    argIds.forEach((aid, i) => {
        const sid = `${id}-arg${i}`;
        target.blocks.createBlock({
            id: sid, opcode: 'text', inputs: {}, fields: {TEXT: {name: 'TEXT', value: String(args[i])}},
            next: null, parent: id, shadow: true, topLevel: false
        });
        inputs[aid] = {name: aid, block: sid, shadow: sid};
    });
    target.blocks.createBlock({
        id: id, opcode: 'procedures_call', inputs: inputs, fields: {}, next: null, parent: null,
        shadow: false, topLevel: true,
        mutation: {tagName: 'mutation', children: [], proccode: proccode, argumentids: JSON.stringify(argIds),
            warp: 'false'}
    });
    return vm.runtime._pushThread(id, target);
}

function setVariables (target, values) {
    const scopes = [target, target.runtime.getTargetForStage()];
    for (const [name, value] of Object.entries(values)) {
        const v = scopes.map(t => Object.values(t.variables).find(x => x.name === name && x.type === ''))
            .find(Boolean);
        if (!v) throw new Error(`no variable ${JSON.stringify(name)} in ${target.getName()}`);
        v.value = value;
    }
}

function active (vm) {
    return vm.runtime.threads.some(t => !t.updateMonitor && !t.isKilled);
}

function runUntilDone (vm, limitMs) {
    const t0 = Date.now();
    let steps = 0;
    while (active(vm)) {
        vm.runtime._step();
        steps++;
        if (Date.now() - t0 > limitMs) return {steps, done: false};
    }
    return {steps, done: true};
}

function readTarget (target, read) {
    const out = {lists: {}, variables: {}};
    // with neither given, everything; with one given, only what was asked for
    const some = read && (read.lists || read.variables);
    const wantLists = some ? (read.lists || []) : null;
    const wantVars = some ? (read.variables || []) : null;
    const scopes = target.isStage ? [target] : [target.runtime.getTargetForStage(), target];
    for (const scope of scopes) {
        for (const v of Object.values(scope.variables)) {
            if (v.type === 'list') {
                if (!wantLists || wantLists.includes(v.name)) out.lists[v.name] = v.value.slice();
            } else if (v.type === '' || v.type === undefined) {
                if (!wantVars || wantVars.includes(v.name)) out.variables[v.name] = v.value;
            }
        }
    }
    return out;
}

async function loadAll (vm, plan, baseDir) {
    const resolve = p => path.resolve(baseDir, p);
    const validation = [];
    const toValidate = plan.validate || [plan.load, ...(plan.sprites || [])].filter(Boolean);
    for (const file of toValidate) {
        const buf = fs.readFileSync(resolve(file));
        const res = await validate(buf, isSpriteFile(file, buf));
        validation.push(Object.assign({file}, res));
    }
    if (plan.project) {
        await vm.loadProject(JSON.stringify(plan.project));
    } else if (plan.load) {
        const buf = fs.readFileSync(resolve(plan.load));
        if (isSpriteFile(plan.load, buf)) {
            // a sprite on its own: load an empty project, then add it
            await vm.loadProject(JSON.stringify(emptyProject(vm)));
            await vm.addSprite(buf);
        } else {
            await vm.loadProject(buf);
        }
    } else {
        await vm.loadProject(JSON.stringify(emptyProject(vm)));
    }
    for (const s of plan.sprites || []) await vm.addSprite(fs.readFileSync(resolve(s)));
    return validation;
}

function isZipPlan (plan, baseDir) {
    if (plan.project) return false;
    if (!plan.load) return true; // an empty project plus sprites
    const fd = fs.openSync(path.resolve(baseDir, plan.load), 'r');
    const head = Buffer.alloc(2);
    fs.readSync(fd, head, 0, 2, 0);
    fs.closeSync(fd);
    return head.toString('latin1') === 'PK';
}

function emptyProject (vm) {
    // the backdrop is ScratchStorage's built-in default vector asset, so it loads without a file
    const storage = vm.runtime.storage;
    const md5 = storage ? storage.defaultAssetId.ImageVector : '8e768a5a5a01891b05c01c9ca15eb6aa';
    return {
        targets: [{isStage: true, name: 'Stage', variables: {}, lists: {}, broadcasts: {}, blocks: {}, comments: {},
            currentCostume: 0, costumes: [{name: 'backdrop1', assetId: md5, md5ext: `${md5}.svg`, dataFormat: 'svg',
                bitmapResolution: 1, rotationCenterX: 1, rotationCenterY: 1}], sounds: [], volume: 100}],
        meta: {semver: '3.0.0'}
    };
}

// several plans in one process (one fresh VM each): {"jobs": [plan, ...]} -> {"jobs": [result, ...]}
async function runJobs (jobs, baseDir) {
    const out = {jobs: []};
    for (const job of jobs) out.jobs.push(await main(job, baseDir, false));
    process.stdout.write(JSON.stringify(out) + '\n');
    return out;
}

async function main (plan, baseDir, print = true) {
    const logs = quietLogs();
    const result = {
        versions: {node: process.version, 'scratch-vm': readVersion('scratch-vm'),
            'scratch-parser': readVersion('scratch-parser')},
        validation: [], runs: []
    };
    try {
        const vm = makeVM(isZipPlan(plan, baseDir));
        result.validation = await loadAll(vm, plan, baseDir);
        const counter = instrument(vm);
        const strokes = {on: false, list: []};
        attachPenRecorder(vm, strokes);
        for (const run of plan.runs || []) {
            counter.total = 0;
            counter.byOpcode = run.opcodes ? {} : null;
            strokes.on = Boolean(run.pen);
            strokes.list = [];
            if (run.set) setVariables(findTarget(vm, run.set.target), run.set.variables || {});
            const t0 = process.hrtime.bigint();
            if (run.greenFlag) vm.greenFlag();
            if (run.call) pushCall(vm, findTarget(vm, run.call.target), run.call.proccode, run.call.args);
            const st = runUntilDone(vm, run.limitMs || 120000);
            const ms = Number(process.hrtime.bigint() - t0) / 1e6;
            const readName = run.read && 'target' in run.read ? run.read.target : (run.call ? run.call.target : undefined);
            const out = Object.assign({blocks: counter.total, steps: st.steps, ms: ms, done: st.done},
                readTarget(findTarget(vm, readName), run.read));
            if (run.opcodes) out.byOpcode = counter.byOpcode;
            if (run.pen) out.pen = strokes.list;
            result.runs.push(out);
            vm.stopAll();
        }
        vm.quit();
    } catch (e) {
        result.error = (e && e.stack) ? e.stack : String(e);
    }
    if (print) process.stdout.write(JSON.stringify(result) + '\n');
    return result;
}

function parseArgs (argv) {
    const plan = {runs: []};
    let baseDir = process.cwd();
    let call = null;
    let target;
    let args = [];
    const read = {};
    let green = false;
    let pen = false;
    let validateOnly = false;
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
        } else if (a === '--validate-only') validateOnly = true;
        else if (a === '--green-flag') green = true;
        else if (a === '--call') call = next();
        else if (a === '--target') target = next();
        else if (a === '--args') args = JSON.parse(next());
        else if (a === '--lists') read.lists = next().split(',').filter(Boolean);
        else if (a === '--vars') read.variables = next().split(',').filter(Boolean);
        else if (a === '--pen') pen = true;
        else if (a === '-h' || a === '--help') {
            process.stdout.write(fs.readFileSync(__filename, 'utf8').split('*/')[0]);
            process.exit(0);
        } else if (!plan.load) plan.load = a;
        else throw new Error(`unexpected argument ${a}`);
    }
    if (!plan.load) throw new Error('no project given (see --help)');
    if (!validateOnly && (green || call)) {
        const run = {greenFlag: green, pen: pen, read: read};
        if (call) run.call = {target: target, proccode: call, args: args};
        if (target !== undefined) run.read.target = target;
        plan.runs.push(run);
    } else if (!validateOnly) {
        plan.runs.push({read: read});
    }
    return {plan, baseDir};
}

if (require.main === module) {
    const fail = e => {
        process.stdout.write(JSON.stringify({error: (e && e.stack) ? e.stack : String(e), validation: [], runs: []}) +
            '\n');
        process.exit(3);
    };
    process.on('uncaughtException', fail);
    process.on('unhandledRejection', fail);
    let parsed;
    try {
        parsed = parseArgs(process.argv.slice(2));
    } catch (e) {
        process.stderr.write(`run.js: ${e.message}\n`);
        process.exit(2);
    }
    const go = parsed.plan.jobs ? runJobs(parsed.plan.jobs, parsed.baseDir) : main(parsed.plan, parsed.baseDir);
    go.then(res => {
        const all = res.jobs || [res];
        const invalid = all.some(r => r.validation.some(v => !v.ok));
        if (res.jobs) res.error = all.some(r => r.error) ? 'a job failed' : undefined;
        // exitCode, not process.exit(): exiting at once can cut off piped stdout at 64 KiB
        process.exitCode = res.error ? 3 : (invalid ? 1 : 0);
    });
}

module.exports = {main, validate};
