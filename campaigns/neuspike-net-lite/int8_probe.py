"""Issue 59 item 4: the spike-only student's network alone at 400x250 (the timing scene's representation as
input), eager and compiled float32, compiled bfloat16, and int8 (PT2E with X86InductorQuantizer's default config,
calibrated on the same input, compiled by inductor with freezing). A measurement, not a shipped path: it needs
torchao, which the project does not depend on (``pip install torchao``, then uninstall).

    python campaigns/neuspike-net-lite/int8_probe.py [THREADS]
"""
import copy
import json
import sys
import time

import torch
from bench.harness.timer import representative_sample
from neuspike.methods import entry
from neuspike.nets import LITE_DESIGN
from neuspike.nets.method import NeuSpikeNetMethod
from safetensors.torch import load_file

threads = int(sys.argv[1]) if len(sys.argv) > 1 else 2
torch.set_num_threads(threads)
torch._inductor.config.freezing = True
e = entry("neuspike-net-spike")
m = NeuSpikeNetMethod("s", **{**e.params, **LITE_DESIGN})
net = m.build_module().eval()
state = load_file("campaigns/neuspike-net-lite/weights.safetensors")
own = net.state_dict()
net.load_state_dict({k: state[k].float() for k in own}, strict=True)
sample = representative_sample(400, 250, modalities=("spikes",))
inputs = tuple(m.encode(sample)[0])

def timeit(fn, n=15):
    for _ in range(3):
        fn()
    ts = []
    for _ in range(n):
        t0 = time.perf_counter(); fn(); ts.append(time.perf_counter() - t0)
    ts.sort(); return 1000 * ts[len(ts) // 2]

out = {}
with torch.no_grad():
    ref = net(*inputs).float()
    out["float32 eager"] = timeit(lambda: net(*inputs))
    c32 = torch.compile(copy.deepcopy(net))
    out["float32 compiled"] = timeit(lambda: c32(*inputs))
    with torch.autocast("cpu", dtype=torch.bfloat16):
        cbf = torch.compile(copy.deepcopy(net))
        out["bfloat16 compiled"] = timeit(lambda: cbf(*inputs))
    from torchao.quantization.pt2e.quantize_pt2e import convert_pt2e, prepare_pt2e
    import torchao.quantization.pt2e.quantizer.x86_inductor_quantizer as xiq
    q = xiq.X86InductorQuantizer(); q.set_global(xiq.get_default_x86_inductor_quantization_config())
    exported = torch.export.export(copy.deepcopy(net), inputs).module()
    prepared = prepare_pt2e(exported, q)
    prepared(*inputs)
    converted = convert_pt2e(prepared)
    cq = torch.compile(converted)
    got = cq(*inputs).float()
    out["int8 compiled"] = timeit(lambda: cq(*inputs))
    out["int8 max |diff| from float32"] = float((got - ref).abs().max())
print(json.dumps({"threads": threads, **{k: round(v, 4) for k, v in out.items()}}, indent=1))
