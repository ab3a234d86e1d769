# Denoise a Mitsuba 3 render in the same process (docs/PYTHON.md).
import mitsuba as mi, numpy as np, filterjit

mi.set_variant("llvm_ad_rgb")
scene = mi.cornell_box()
aovs = "albedo:albedo,sh_normal:sh_normal,position:position"
scene["integrator"] = {"type": "aov", "aovs": aovs, "integrator": {"type": "path"}}
image = np.array(mi.render(mi.load_dict(scene), spp=4), dtype=np.float32)
# Channels: R, G, B, then each AOV in the order named.
color, albedo, normal, position = (np.ascontiguousarray(image[..., k:k + 3]) for k in (0, 3, 6, 9))

out = filterjit.denoise(color, albedo=albedo, normal=normal, position=position)

scene["integrator"] = {"type": "path"}
reference = np.array(mi.render(mi.load_dict(scene), spp=256), dtype=np.float32)
print(f"relMSE noisy {filterjit.relmse(color, reference):.4f} -> {filterjit.relmse(out, reference):.4f} "
      f"with {filterjit.choose(['albedo', 'normal', 'position'])[0]}")
