// Parses a G-code file with the npm package gcode-parser (the parser behind cncjs), line by line
// with parseLine and no result accumulation (its fastest use), and prints "lines best-seconds words" (best of N runs, default 3).
// File reading and line splitting are left out of the timing, in the package's favour.
const fs = require('fs');
const parser = require('gcode-parser');
const text = fs.readFileSync(process.argv[2], 'utf8');
const lines = text.split('\n');
const repeats = Number(process.argv[3] || 3);
let best = Infinity;
let words = 0;
for (let r = 0; r < repeats; r++) {
  words = 0;
  const start = process.hrtime.bigint();
  for (let i = 0; i < lines.length; i++) {
    const result = parser.parseLine(lines[i]);
    words += result.words.length;
  }
  best = Math.min(best, Number(process.hrtime.bigint() - start) / 1e9);
}
console.log(lines.length + ' ' + best + ' ' + words);
