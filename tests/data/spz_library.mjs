// Runs the official SPZ library (nianticlabs/spz as WebAssembly, npm @adobe/spz) for
// tests/formats/test_interop_splat_transform.py; splat-transform's npm package brings it along.
//
//   node spz_library.mjs LIB enum                      -> {"RUB": 4, ...} (CoordinateSystem)
//   node spz_library.mjs LIB load FILE TO              -> {"positions": [...], "extensions": [...]}
//   node spz_library.mjs LIB save IN OUT TO FROM VER   -> loads IN converted to TO, saves OUT
//                                                          from FROM as version VER (8-bit SH)
//
// LIB is the path of @adobe/spz's dist/spz.js; TO and FROM name a CoordinateSystem
// (UNSPECIFIED: no conversion).  Extensions a loaded file carries are saved again.
import { readFileSync, writeFileSync } from 'node:fs';
import { pathToFileURL } from 'node:url';

const [lib, command, ...args] = process.argv.slice(2);
const { default: createModule } = await import(pathToFileURL(lib).href);
const spz = await createModule({ print: () => {}, printErr: () => {} });
const system = (name) => {
    if (!(name in spz.CoordinateSystem)) throw new Error(`unknown coordinate system ${name}`);
    return spz.CoordinateSystem[name];
};
const code = (value) => (typeof value === 'object' ? value.value : value);
const load = (file, to) => {
    const cloud = spz.loadSpzFromBuffer(new Uint8Array(readFileSync(file)), { to: system(to) });
    if (!cloud.numPoints) throw new Error(`the library could not load ${file}`);
    return cloud;
};

if (command === 'enum') {
    const out = {};
    for (const name of Object.keys(spz.CoordinateSystem)) {
        if (/^[A-Z]+$/.test(name)) out[name] = code(spz.CoordinateSystem[name]);
    }
    console.log(JSON.stringify(out));
} else if (command === 'load') {
    const cloud = load(args[0], args[1]);
    console.log(JSON.stringify({
        positions: Array.from(cloud.positions),
        extensions: Array.from(cloud.extensions, (e) => [code(e.extensionType) >>> 0,
            e.coordinateSystem === undefined ? null : code(e.coordinateSystem)])
    }));
} else if (command === 'save') {
    const [input, output, to, from, version] = args;
    const cloud = load(input, to);
    const bytes = spz.saveSpzToBuffer(cloud, {
        version: Number(version), from: system(from), sh1Bits: 8, shRestBits: 8
    });
    writeFileSync(output, bytes);
} else {
    throw new Error(`unknown command ${command}`);
}
