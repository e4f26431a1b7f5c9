"""Clean Up Unused Results, and the render-time warning about result files that are missing.

Recomputing never deletes a result's files (a saved .blend or the undo stack may read them),
so they pile up in the output folder; this operator lists and removes the ones that neither the
open .blend, nor any .blend beside it, nor the .blend files it is given reads.
"""

import os

import bpy
from bpy.app.handlers import persistent
from bpy.props import BoolProperty, StringProperty

from . import operators, results


def output_folders():
    """The folders results go to or are read from: each volume's Output folder and the
    folders of the files result volumes read."""
    out = set()
    for ob in bpy.data.objects:
        if ob.type == 'VOLUME' or ob.get(results.RESULT_TAG):
            out.add(operators._out_dir(ob.volscatter))
    for vol in bpy.data.volumes:
        for p in results.volume_files(vol)[:1]:
            out.add(os.path.dirname(p))
    return sorted(f for f in out if os.path.isdir(f))


def blends_to_keep(extra):
    """The saved .blend files whose results are kept: those beside the open file and beside
    the output folders (a project's versions), and `extra` (";"-separated paths)."""
    out = set()
    folders = set(output_folders())
    if bpy.data.filepath:
        folders.add(os.path.dirname(bpy.data.filepath))
    for folder in folders:
        out.update(results.blends_beside(folder))
        out.update(results.blends_beside(os.path.dirname(folder)))
    for p in (extra or "").split(";"):
        p = p.strip()
        if p:
            out.add(os.path.normpath(bpy.path.abspath(p)))
    return sorted(out)


class VOLSCATTER_OT_clean_up_results(bpy.types.Operator):
    """Delete the result files that no open or saved .blend uses"""

    bl_idname = "volscatter.clean_up_results"
    bl_label = "Clean Up Unused Results"
    bl_options = {'REGISTER'}

    blend_files: StringProperty(name="Also Keep For", default="",
                                description="More .blend files whose results are kept (paths separated by ';')")
    dry_run: BoolProperty(name="List Only", default=False, description="List the files without deleting them")

    def _unused(self):
        blends = blends_to_keep(self.blend_files)
        missing = [b for b in blends if not os.path.isfile(b)]
        if missing:
            raise FileNotFoundError("no such .blend: %s" % ", ".join(missing))
        return results.unused_files(output_folders(), blends), blends

    def invoke(self, context, event):
        try:
            self._files, _ = self._unused()
        except Exception as e:
            self.report({'ERROR'}, "volscatter: %s" % e)
            return {'CANCELLED'}
        if not self._files:
            self.report({'INFO'}, "volscatter: no unused result files")
            return {'CANCELLED'}
        return context.window_manager.invoke_props_dialog(self, width=500)

    def draw(self, context):
        col = self.layout.column()
        col.label(text="Delete %d file%s that no .blend uses:" % (len(self._files), "" if len(self._files) == 1 else "s"))
        for p in self._files[:12]:
            col.label(text=os.path.basename(p))
        if len(self._files) > 12:
            col.label(text="... and %d more" % (len(self._files) - 12))

    def execute(self, context):
        try:
            files, blends = self._unused()  # again: a .blend may have been saved since invoke
        except Exception as e:
            self.report({'ERROR'}, "volscatter: %s" % e)
            return {'CANCELLED'}
        if self.dry_run:
            for p in files:
                self.report({'INFO'}, "volscatter: unused: %s" % p)
            self.report({'INFO'}, "volscatter: %d unused result file%s (checked %d .blend file%s)"
                        % (len(files), "" if len(files) == 1 else "s", len(blends), "" if len(blends) == 1 else "s"))
            return {'FINISHED'}
        removed = 0
        for p in files:
            try:
                os.remove(p)
                removed += 1
            except OSError as e:
                self.report({'WARNING'}, "volscatter: cannot delete %s: %s" % (p, e))
        self.report({'INFO'}, "volscatter: deleted %d unused result file%s (kept what %d .blend file%s and this one use)"
                    % (removed, "" if removed == 1 else "s", len(blends), "" if len(blends) == 1 else "s"))
        return {'FINISHED'}


@persistent
def warn_missing_at_render(scene, *_):
    """Says, on the console, which results a render shows without their files."""
    for w in results.render_warnings(scene):
        print("Warning: " + w)


classes = (VOLSCATTER_OT_clean_up_results,)


def register():
    for c in classes:
        bpy.utils.register_class(c)
    bpy.app.handlers.render_init.append(warn_missing_at_render)


def unregister():
    if warn_missing_at_render in bpy.app.handlers.render_init:
        bpy.app.handlers.render_init.remove(warn_missing_at_render)
    for c in reversed(classes):
        bpy.utils.unregister_class(c)
