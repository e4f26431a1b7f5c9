// SPDX-License-Identifier: GPL-3.0-or-later
// Flamenco job type: bake volscatter's multiple scattering for a USD stage's frame range.
// Copy into the `scripts/` folder beside flamenco-manager (docs/farm.md). Each chunk of frames
// is one task running `volscatter-usd bake --frames A-B` (one native session per chunk; frames
// the manifest already holds are skipped, so a re-queued task redoes only what is missing); a
// last task, after every chunk, runs the whole range again: every frame is skipped and the
// layer is written listing all of them.

const JOB_TYPE = {
    label: "volscatter USD bake",
    settings: [
        { key: "stage", type: "string", subtype: "file_path", required: true,
          description: "The USD stage to bake (a path every worker can read)" },
        { key: "out_layer", type: "string", subtype: "file_path", required: true,
          description: "The layer to write; VDBs and the manifest go beside it" },
        { key: "frames", type: "string", required: true,
          description: "Frame range, A-B (e.g. 1-240)" },
        { key: "chunk_size", type: "int32", default: 24, propargs: { min: 1 },
          description: "Frames per task (one native session each)" },
        { key: "solver", type: "string", default: "auto",
          description: "A solver of the library's registry (volscatter solvers)" },
        { key: "extra_args", type: "string", default: "",
          description: "More volscatter-usd bake arguments, space-separated (e.g. --set output_resolution=96)" },
        { key: "exe", type: "string", default: "volscatter-usd",
          description: "The volscatter-usd command on the workers" },
    ]
};

function bakeArgs(settings, frames) {
    const args = ["bake", settings.stage, "--frames", frames, "--out-layer", settings.out_layer,
                  "--solver", settings.solver, "-q"];
    const extra = (settings.extra_args || "").trim();
    return extra ? args.concat(extra.split(/\s+/)) : args;
}

function compileJob(job) {
    const settings = job.settings;
    const chunkTasks = [];
    for (const chunk of frameChunker(settings.frames, settings.chunk_size)) {
        // frameChunker gives "A-B" (or "A" for a one-frame chunk)
        const frames = chunk.includes("-", 1) ? chunk : `${chunk}-${chunk}`;
        const task = author.Task(`bake-${chunk}`, "misc");
        task.addCommand(author.Command("exec", { exe: settings.exe, args: bakeArgs(settings, frames) }));
        job.addTask(task);
        chunkTasks.push(task);
    }
    const layer = author.Task("layer", "misc");
    layer.addCommand(author.Command("exec", { exe: settings.exe, args: bakeArgs(settings, settings.frames) }));
    for (const t of chunkTasks) {
        layer.addDependency(t);
    }
    job.addTask(layer);
}
