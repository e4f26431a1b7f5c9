// SPDX-License-Identifier: GPL-3.0-or-later
// Flamenco job type: volscatter's headless Blender bake of one object over a frame range
// (`blender -b FILE.blend --python .../volscatter_blender/bake.py -- --object NAME --frames A-B`).
// Copy into the `scripts/` folder beside flamenco-manager (docs/farm.md). One task per chunk;
// frames whose files match the manifest are skipped, so a re-queued task redoes only what is
// missing. Submitted from Blender, `frames` and `blendfile` fill themselves in.

const JOB_TYPE = {
    label: "volscatter Blender bake",
    settings: [
        { key: "blendfile", type: "string", subtype: "file_path", required: true, visible: "web",
          description: "The .blend to bake from" },
        { key: "object", type: "string", required: true, eval: "C.object.name",
          description: "The Volume object (or Mantaflow smoke domain) to bake" },
        { key: "frames", type: "string", required: true,
          eval: "f'{C.scene.frame_start}-{C.scene.frame_end}'",
          description: "Frame range, A-B" },
        { key: "chunk_size", type: "int32", default: 24, propargs: { min: 1 },
          description: "Frames per task (one native session each)" },
        { key: "out_dir", type: "string", subtype: "dir_path", required: true,
          description: "Where the VDBs and the manifest go (a path every worker can write)" },
        { key: "bake_script", type: "string", subtype: "file_path", required: true,
          description: "volscatter_blender/bake.py of the add-on as installed on the workers" },
    ]
};

function compileJob(job) {
    const settings = job.settings;
    for (const chunk of frameChunker(settings.frames, settings.chunk_size)) {
        const frames = chunk.includes("-", 1) ? chunk : `${chunk}-${chunk}`;
        const task = author.Task(`bake-${chunk}`, "blender");
        task.addCommand(author.Command("blender-render", {
            exe: "{blender}",
            exeArgs: "{blenderArgs}",
            argsBefore: [],
            blendfile: settings.blendfile,
            args: ["--python", settings.bake_script, "--", "--object", settings.object, "--frames", frames,
                   "--out", settings.out_dir],
        }));
        job.addTask(task);
    }
}
