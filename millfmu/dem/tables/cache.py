"""The tables cache: entries named by the key of their :class:`TableSpec`, built once and
verified on every read, safe against concurrent builders.

The cache lives in ``$MILLFMU_CACHE_DIR``, else ``$XDG_CACHE_HOME/millfmu/tables``, else
``~/.cache/millfmu/tables``; each entry is a folder named by the sha256 of the canonical JSON
of (format, builder, DEM scene content, grid, kernel version). Entries are written into a
temporary folder and renamed into place under an exclusive ``fcntl.flock``; an entry that
fails any check (manifest checksum, file checksums and sizes, key, version, array shapes)
is rebuilt, never used. An entry built by another DEM (:func:`dem_kernel_version`) is stale.

Imports no numba: the DEM's version is a hash of its source files, read, not imported.
"""

from __future__ import annotations

import contextlib
import fcntl
import hashlib
import importlib.util
import json
import os
import re
import shutil
import tempfile
import time
from pathlib import Path
from collections.abc import Callable

from .build import PointStore, build_table, seconds_per_cost
from ...stress_tables.files import fsync_dir
from ...stress_tables.spec import DEM_BUILDER_ID, EARLIER_FORMAT, FORMAT_VERSION, TableError, TableSpec, manifest_for
from ...stress_tables.table import Table, read_table


#: Modules whose source decides the DEM's numbers: contact laws and integration (kernels,
#: sim), the coupled fluid (fluid, coupling), the run loop (run) and what is measured
#: (stats, zones). Their source hash is the kernel version. Label -> module: the hash takes
#: each module's label, its name before the DEM was laid out by role (engine, mills,
#: analysis), so that where a module stands is not part of the version.
KERNEL_MODULES = {
    "millfmu.dem.kernels": "millfmu.dem.engine.kernels",
    "millfmu.dem.sim": "millfmu.dem.engine.sim",
    "millfmu.dem.stats": "millfmu.dem.analysis.stats",
    "millfmu.dem.zones": "millfmu.dem.mills.zones",
    "millfmu.dem.run": "millfmu.dem.run",
    "millfmu.dem.fluid.grid": "millfmu.dem.fluid.grid",
    "millfmu.dem.fluid.vans_kernels": "millfmu.dem.fluid.vans_kernels",
    "millfmu.dem.fluid.k_epsilon": "millfmu.dem.fluid.k_epsilon",
    "millfmu.dem.fluid.pressure": "millfmu.dem.fluid.pressure",
    "millfmu.dem.fluid.solver": "millfmu.dem.fluid.solver",
    "millfmu.dem.coupling.projection": "millfmu.dem.coupling.projection",
    "millfmu.dem.coupling.koch_hill2001": "millfmu.dem.engine.koch_hill2001",
    # wet restitution per contact (off unless a scene names it)
    "millfmu.dem.engine.legendre2006": "millfmu.dem.engine.legendre2006",
    "millfmu.dem.coupling.cfd_dem": "millfmu.dem.coupling.cfd_dem",
    "millfmu.dem.coupling.settings": "millfmu.dem.coupling.settings",
    # the pressure equation's solvers and default, moved out of coupling.settings
    "millfmu.dem.fluid.settings": "millfmu.dem.fluid.settings",
    "millfmu.dem.coupling.dpm": "millfmu.dem.coupling.dpm",
    "millfmu.dem.coupling.schiller_naumann": "millfmu.dem.coupling.schiller_naumann",
    "millfmu.dem.coupling.split_implicit_smoothing":
        "millfmu.dem.coupling.split_implicit_smoothing",
    "millfmu.dem.fluid.theta_fft_pressure": "millfmu.dem.fluid.theta_fft_pressure",
    "millfmu.dem.fluid.ldl_pressure": "millfmu.dem.fluid.ldl_pressure",
    # the coupled step's kernels and the one set of numba flags (fastmath, error model)
    "millfmu.dem.coupling.exchange_kernels": "millfmu.dem.coupling.exchange_kernels",
    "millfmu.dem.fluid.step_kernels": "millfmu.dem.fluid.step_kernels",
    "millfmu.dem.engine._jit": "millfmu.dem.engine._jit",
    # how the threads share out the chunks (the same results on any schedule)
    "millfmu.dem.engine.chunk_claims": "millfmu.dem.engine.chunk_claims",
    # the coupled exchange in one compiled call (the same kernels in the same order)
    "millfmu.dem.coupling.fused_exchange": "millfmu.dem.coupling.fused_exchange",
    # the neighbour lists carried through a reordering of the beads
    "millfmu.dem.engine.reorder": "millfmu.dem.engine.reorder",
    # model A's beads' share of the viscous stress (off unless a scene names it)
    "millfmu.dem.fluid.anderson_jackson1967": "millfmu.dem.fluid.anderson_jackson1967",
}

#: Source hash -> the kernel version it stands for, where sources changed without changing
#: what the DEM computes: each entry is added only when runs of the changed sources (coupled
#: and plain sectors, an accelerator slice, on 1 and 2 threads, numba's cache emptied first)
#: give the same beads, forces, liquid and recorded contacts to the bit as runs of the
#: sources before. The shipped tables record the version of the sources they were built
#: with, which stays the version; a checkpoint made by one of these sources resumes under
#: another (run.resume_run). Any other change of these sources gives a new hash, and a new
#: version. An entry may also map to the source hash of a round-off change accepted on
#: evidence (:mod:`millfmu.dem.tables.equivalence`): sources the same to the bit as those,
#: which take the version that change was accepted as. What each entry's change was:
#: CHANGELOG.md.
SAME_DEM_AS = {
    "sha256:50c71a6d91ca3ead7c3ae29058f6eeaa5d22a0a91394c8be4533dd97437308d3":
        "sha256:cc5c174862c188a675fdb35932f269eb61ae82876e3d110866af2b7a62b0d3bd",
    "sha256:481d167006290e736566cf2fdeef09310c9e22b4dc250f4499a75706e09c8471":
        "sha256:cc5c174862c188a675fdb35932f269eb61ae82876e3d110866af2b7a62b0d3bd",
    "sha256:332ba9f69ed3ede1421cb05870278a7c96398ae56afac264b63b7735668e0258":
        "sha256:cc5c174862c188a675fdb35932f269eb61ae82876e3d110866af2b7a62b0d3bd",
    "sha256:4f0be1f5c60bc72ea6f35afef4fef8979fcef21bdcc60d2b32f986b62750b350":
        "sha256:cc5c174862c188a675fdb35932f269eb61ae82876e3d110866af2b7a62b0d3bd",
    "sha256:562d77630841edf661764954655b9250be192612da39bdd27bef81dbda6edf51":
        "sha256:cc5c174862c188a675fdb35932f269eb61ae82876e3d110866af2b7a62b0d3bd",
    "sha256:eb63ffecd754ccc40f3a503755a0a48812180deaa050c048fddbf8b57e7a9788":
        "sha256:cc5c174862c188a675fdb35932f269eb61ae82876e3d110866af2b7a62b0d3bd",
    "sha256:4e5f649d8459bddd50a7ec059ace6b44106bac1745e88635e4f565af91d91452":
        "sha256:cc5c174862c188a675fdb35932f269eb61ae82876e3d110866af2b7a62b0d3bd",
    "sha256:028e85988f93ae985f0b0c72fbde33da900d4bcc2fb1c7c492fc5100b4044ad9":
        "sha256:cc5c174862c188a675fdb35932f269eb61ae82876e3d110866af2b7a62b0d3bd",
    "sha256:f632de0f2869352b3cef8fd19ea903595299584da8a134ca8c02969fe849e5f0":
        "sha256:cc5c174862c188a675fdb35932f269eb61ae82876e3d110866af2b7a62b0d3bd",
    "sha256:b483f9ccb53f05e0eebedf29f14b124bbf437a79bd04435ca164748178624f0f":
        "sha256:cc5c174862c188a675fdb35932f269eb61ae82876e3d110866af2b7a62b0d3bd",
    "sha256:67aca0eac7b6d50810ff548dc468ce3bcf434a96367e5b4e832e9f8723d62fd5":
        "sha256:cc5c174862c188a675fdb35932f269eb61ae82876e3d110866af2b7a62b0d3bd",
    "sha256:4ac8087367f9e1c93254e12ca4dfcf41ecbf54f0f1de3c275859a607890cf4c3":
        "sha256:cc5c174862c188a675fdb35932f269eb61ae82876e3d110866af2b7a62b0d3bd",
    "sha256:97dc65883fc041bfc0693d423f78d410ca358029a1eae46d45a8c8b5397272cc":
        "sha256:cc5c174862c188a675fdb35932f269eb61ae82876e3d110866af2b7a62b0d3bd",
    "sha256:34bc597760eae87a00ea904b22f9b0b986db8ab1545f831173e8341684f37a89":
        "sha256:cc5c174862c188a675fdb35932f269eb61ae82876e3d110866af2b7a62b0d3bd",
    "sha256:1f26a6d8d9f7ce97b3606c5143fbc3d2ae445afd3b9e337557f8178eea4db22d":
        "sha256:cc5c174862c188a675fdb35932f269eb61ae82876e3d110866af2b7a62b0d3bd",
    "sha256:fd656f5742f3053fc067f26f665e049b94646bea8e2a0c97ce58c5f3e8077676":
        "sha256:cc5c174862c188a675fdb35932f269eb61ae82876e3d110866af2b7a62b0d3bd",
    "sha256:440c9e86aca0bd2dc3fa7c9f3c760c44ae5b50b1ee8d53ef97d67317ced8684e":
        "sha256:cc5c174862c188a675fdb35932f269eb61ae82876e3d110866af2b7a62b0d3bd",
    "sha256:71aff4427c81e0c03bf765726fffe34203be9ddcf975680f01667e53e7c6f2a1":
        "sha256:cc5c174862c188a675fdb35932f269eb61ae82876e3d110866af2b7a62b0d3bd",
    "sha256:6b286e37b124290f387cd763133f2d9dc64435ae3cfcc08aabca224eb10fd33a":
        "sha256:cc5c174862c188a675fdb35932f269eb61ae82876e3d110866af2b7a62b0d3bd",
    "sha256:a41ae236e3021380e493b51d2994e88f02ae008740069460f87480d511ed4166":
        "sha256:cc5c174862c188a675fdb35932f269eb61ae82876e3d110866af2b7a62b0d3bd",
    "sha256:3b11d2b507e64d077a42ad58744665be5d5f15f5b1ffca47626d06b58b0d2b7b":
        "sha256:cc5c174862c188a675fdb35932f269eb61ae82876e3d110866af2b7a62b0d3bd",
    "sha256:77b707345135db3ad3a1943408b6ec26bfa2e8b0adfd0e600b9104395c998536":
        "sha256:cc5c174862c188a675fdb35932f269eb61ae82876e3d110866af2b7a62b0d3bd",
    "sha256:c1be632cc2eb93fc6f74bebafdaaa0a44426ef348b1bcb2efdaaba1defcc4b93":
        "sha256:cc5c174862c188a675fdb35932f269eb61ae82876e3d110866af2b7a62b0d3bd",
    "sha256:960091580bd02eb91882afa454c32cb9b20a4083cd3eeffc01c076228a3abceb":
        "sha256:cc5c174862c188a675fdb35932f269eb61ae82876e3d110866af2b7a62b0d3bd",
    "sha256:4d8cef38c8109883e91e3c24cfeffe5b9b82172122d298f1edd749e6dfbe7b94":
        "sha256:cc5c174862c188a675fdb35932f269eb61ae82876e3d110866af2b7a62b0d3bd",
    "sha256:a81e8a1df05611dcbd873c9cada9a738180aa03ceb55692f7114780ca7d00738":
        "sha256:cc5c174862c188a675fdb35932f269eb61ae82876e3d110866af2b7a62b0d3bd",
    "sha256:4afb54364059ef99ca9791e1de6acda80b84ee06de65e2cac5b2f9925f40578a":
        "sha256:cc5c174862c188a675fdb35932f269eb61ae82876e3d110866af2b7a62b0d3bd",
    "sha256:2fa658bbb59da52cfcb10a1472d1ac8861ed641cc0ed01aaaf8d019573a05382":
        "sha256:cc5c174862c188a675fdb35932f269eb61ae82876e3d110866af2b7a62b0d3bd",
    "sha256:4b9208ba6080af5e8bd169bf37178985a5e29ec39873be34a8a848f549927b99":
        "sha256:cc5c174862c188a675fdb35932f269eb61ae82876e3d110866af2b7a62b0d3bd",
    "sha256:eba119aae07c01d0288ab74d83b90f61bc34294cb2a83b826ea1eebd1b22b5c6":
        "sha256:cc5c174862c188a675fdb35932f269eb61ae82876e3d110866af2b7a62b0d3bd",
    "sha256:5207b2b0d73dd3b0fd783b1bc3ef990da5e2059c870de59f2a2fe92e1d74c831":
        "sha256:cc5c174862c188a675fdb35932f269eb61ae82876e3d110866af2b7a62b0d3bd",
    "sha256:aff26d9e8c03c48c62bd8a321f93b74e017f563bd5b28df2240e907bdb7f1d3a":
        "sha256:cc5c174862c188a675fdb35932f269eb61ae82876e3d110866af2b7a62b0d3bd",
    "sha256:6d4572076a746ea46398bc337a67704dde5c0b2e3aaa51b4aa473b764906332d":
        "sha256:cc5c174862c188a675fdb35932f269eb61ae82876e3d110866af2b7a62b0d3bd",
    "sha256:d6b0665ee6306f42530ba8f29ff4afa07e60689f9863b07a860415558fe59f08":
        "sha256:cc5c174862c188a675fdb35932f269eb61ae82876e3d110866af2b7a62b0d3bd",
    "sha256:a918b0919a96770cf3cb258766c1057dc780524a61ac831e327919384a5bf507":
        "sha256:cc5c174862c188a675fdb35932f269eb61ae82876e3d110866af2b7a62b0d3bd",
    "sha256:ca031c44b723e5de37154318c204db8608e5cb76f8b31e08e9b8ff2ca3e445c8":
        "sha256:cc5c174862c188a675fdb35932f269eb61ae82876e3d110866af2b7a62b0d3bd",
    "sha256:5b4f2ef30188b94bb56c6a48c6eb6b4661a14a2bef0fe85a734329c8d098f23d":
        "sha256:cc5c174862c188a675fdb35932f269eb61ae82876e3d110866af2b7a62b0d3bd",
    "sha256:f6d70edf289446eb2aebcb7607e71b6527f07d7e37bb34b79743c9a4e990c1aa":
        "sha256:cc5c174862c188a675fdb35932f269eb61ae82876e3d110866af2b7a62b0d3bd",
    "sha256:c17be759cb39af8022bc70c507c86fe8f1de5bbe004ce269db39f6464ff10fa0":
        "sha256:cc5c174862c188a675fdb35932f269eb61ae82876e3d110866af2b7a62b0d3bd",
    "sha256:bbc100ab125eacfdd65bd060cbc0f332cd0695d255cc137f7feb68ee834cc7a4":
        "sha256:cc5c174862c188a675fdb35932f269eb61ae82876e3d110866af2b7a62b0d3bd",
    "sha256:cffb4ecbb1e2ff165010083e1467a9f2743b0be6ccc438b60916ce46698497aa":
        "sha256:cc5c174862c188a675fdb35932f269eb61ae82876e3d110866af2b7a62b0d3bd",
    # the same to the bit as the accepted change of the pressure solver's default (its
    # source hash; dem_equivalence.json): the neighbour search's entries by component and
    # tested a run at a time, the beads' wrap on the threads
    "sha256:6e5eb17b6746e294550283bfe62271a52d1de4cdb83b6d64713f89629baf6e6b":
        "sha256:97f753cea048d151d29bfc09ed08fc9161f206eb44b7bf748a0474d96810be97",
    # and the fluid's and the pressure equation's default solver named once, in settings
    # (the same three scenes identical to the bit)
    "sha256:796c5ee39ac30bdd41982b29dde16444868c9a73f71427fc9d3be79d1e470b8d":
        "sha256:97f753cea048d151d29bfc09ed08fc9161f206eb44b7bf748a0474d96810be97",
    # and the pressure module's docstring naming the solvers (a docstring only)
    "sha256:d2096820d2095d34420630dc3285697d045f6a5f4e22a6f7b6597ce68d1b26bb":
        "sha256:97f753cea048d151d29bfc09ed08fc9161f206eb44b7bf748a0474d96810be97",
    # and the neighbour search's vector loop calling axial_image instead of a copy of it,
    # and docstrings (three scenes on 1 thread, the bench bed's 1000 steps on 2: the same)
    "sha256:bb97b33db63f91460c32d5b68addba80298367a6d226725f892ca05c8d579acd":
        "sha256:97f753cea048d151d29bfc09ed08fc9161f206eb44b7bf748a0474d96810be97",
    # and the kernels' compiled code cached in a folder keyed by every kernel file's bytes
    # (where it is kept, not what it computes: three scenes and a 4-theta-cell sector, 1
    # and 2 threads, against the previous sources compiled afresh, the same to the bit)
    "sha256:f4c516f6b843a414ed7048eca49879743a74469baf30ebd86370e67a12735708":
        "sha256:97f753cea048d151d29bfc09ed08fc9161f206eb44b7bf748a0474d96810be97",
    # and the force loop, reduction and neighbour build taking the chunks each thread its
    # own region first (chunk_claims: which thread runs a chunk, not what it computes;
    # three scenes on 1 and 2 threads against the previous sources, the same to the bit)
    "sha256:f1d8588faa54a408b18401d5cbd6e88640cef0b6dade7df6300bc3fcca7c80c7":
        "sha256:97f753cea048d151d29bfc09ed08fc9161f206eb44b7bf748a0474d96810be97",
    # and chunk_claims' docstring with the later measurements (a docstring only)
    "sha256:6c1b4aca393d8e74d105449db73d97fc44c6086d128968b6b11fdd23c6d22fcb":
        "sha256:97f753cea048d151d29bfc09ed08fc9161f206eb44b7bf748a0474d96810be97",
    # and the coupled exchange in one compiled call (fused_exchange: the same kernels, in
    # the same order, with the same arguments; three scenes on 1 and 2 threads against the
    # previous sources, the same to the bit)
    "sha256:c2a52b2afdbe96b38027a3813304b5ce1e7dd653dfce84f8e2e32a55666e857e":
        "sha256:97f753cea048d151d29bfc09ed08fc9161f206eb44b7bf748a0474d96810be97",
    # and the neighbour lists carried through a reordering of the beads by numba loops
    # (reorder: the same lists as the numpy passes, a test keeps those as the reference;
    # three scenes on 1 and 2 threads against the previous sources, the same to the bit)
    "sha256:4c1d1d6daf90010bd28c3ac4639db19acb5079b09f1b035f097d0d7975f7ccee":
        "sha256:97f753cea048d151d29bfc09ed08fc9161f206eb44b7bf748a0474d96810be97",
    # and the liquid's edge stresses, explicit rates, turbulence production and transport
    # with their rows on the threads (each row writes its own nodes; a coupled disc sector
    # from the running mill and from its start, a 4-theta-cell sector, a coupled
    # accelerator slice and one with baffles and k-epsilon, on 1 and 2 threads against the
    # previous sources, the same to the bit)
    "sha256:874a7ca4856c4dcc09104dce45b62fe4211bdd12f93498030bc8deaab9f36fd0":
        "sha256:97f753cea048d151d29bfc09ed08fc9161f206eb44b7bf748a0474d96810be97",
    # and the beads' deposit of six columns as two halves on the threads (each column
    # summed in the beads' order; the same five coupled runs and a discrete-phase sector,
    # on 1 and 2 threads against the previous sources, the same to the bit)
    "sha256:b4d59e9de1b2e4e71b64a1b3e5d9a7c6690b2436fd6447b43e0ff0b94cca9451":
        "sha256:97f753cea048d151d29bfc09ed08fc9161f206eb44b7bf748a0474d96810be97",
    # and an unused local taken out of DemSimulation.run (the same runs the same to the bit)
    "sha256:2fc5cd7de8c6f3376898ac4fb1d9ccf93a1a0add494a722eb7e35f7d21df7e4f":
        "sha256:97f753cea048d151d29bfc09ed08fc9161f206eb44b7bf748a0474d96810be97",
    # and every thread count set through _jit.use_threads, the layer's priority in the
    # environment too (no kernel changed; the same runs the same to the bit)
    "sha256:db6c67ce03440e64635fa5d34c897dee893a77ea16a2f9d867c908aabf3bc621":
        "sha256:97f753cea048d151d29bfc09ed08fc9161f206eb44b7bf748a0474d96810be97",
    # and the kick and drift of the beads that only their own chunk's rows reach done in the
    # force loop (both bench beds with contacts recorded, the coupled and discrete-phase
    # scenes above, on 1 and 2 threads: the same to the bit)
    "sha256:84286cfa7e10190d085cba4f1e1a6333660ed53311911ba44c099b96d052920f":
        "sha256:97f753cea048d151d29bfc09ed08fc9161f206eb44b7bf748a0474d96810be97",
    # and the buffers' read-and-zero as one inlined helper (the same checks, the same bits)
    "sha256:67b181cf65b90fc438303e8f8bc38b017c993f814c1759868eea53a836e5d24c":
        "sha256:97f753cea048d151d29bfc09ed08fc9161f206eb44b7bf748a0474d96810be97",
    # and two docstrings of the kernels rewrapped (no code changed; the bench beds and the
    # coupled scenes the same to the bit)
    "sha256:637be488bf1f1706aac2f45c6bcd61e5ec8b1fb6dede8c457c4e8d5f3f22124e":
        "sha256:97f753cea048d151d29bfc09ed08fc9161f206eb44b7bf748a0474d96810be97",
    # and runs of coupling intervals, each fused exchange and the DEM's steps after it, in
    # one compiled call (the bench bed recorded, the coupled sector, 4 theta cells, the
    # accelerator and the discrete-phase sector unrecorded and recorded, on 1 and 2
    # threads: the same to the bit)
    "sha256:3203b62805bb94bad79251804a869e2d8e1f2732c2fae41c27f97f50be335697":
        "sha256:97f753cea048d151d29bfc09ed08fc9161f206eb44b7bf748a0474d96810be97",
    # and the run's thread setting shared by run() and resume_run(), the event count and
    # accumulator passed to the compiled intervals by name (the same checks, the same bits)
    "sha256:68cf7434cc69873bfc865c86396d5ee325ecc8ae74b0aa17af3984cfe974bf29":
        "sha256:97f753cea048d151d29bfc09ed08fc9161f206eb44b7bf748a0474d96810be97",
    # and the DEM's indices declared non-negative (no wraparound selects; the neighbour
    # search's entries loaded as vectors instead of gathers), the same five cases on 1 and
    # 2 threads: the same to the bit
    "sha256:090ea12805153963c460d5c11f413ef9b7f0afebe31e84b192a4170c295eea6c":
        "sha256:97f753cea048d151d29bfc09ed08fc9161f206eb44b7bf748a0474d96810be97",
    # and the exchange's cell indices declared non-negative, the stencils' periodic
    # indices wrapped without an integer modulo (the same five cases, 1 and 2 threads:
    # the same to the bit)
    "sha256:a0defec8bd18943fa52e17465a59d1c46c6bf3d01d7fe46127c74f39e365d182":
        "sha256:97f753cea048d151d29bfc09ed08fc9161f206eb44b7bf748a0474d96810be97",
    # and the walls out of a near bead's reach or absent skipped before wall_response (the
    # same five cases, 1 and 2 threads: the same to the bit)
    "sha256:6b997db18a29a4b2a49a5ff8de32921d43df6ad6e229ae0235b1d31468654727":
        "sha256:97f753cea048d151d29bfc09ed08fc9161f206eb44b7bf748a0474d96810be97",
    # and the equal-bead check and the binning's cells in loops without an early exit or a
    # histogram (vectorised; the same five cases, 1 and 2 threads: the same to the bit)
    "sha256:f45078aee5ea6a0bdb1a67e9ca3aa2edcef1ad196a81125b4513732d7fe3d85a":
        "sha256:97f753cea048d151d29bfc09ed08fc9161f206eb44b7bf748a0474d96810be97",
    # and a wall's contact released by one helper (the same five cases, 1 and 2 threads: the
    # same to the bit)
    "sha256:79a11383c1dfaace0948bdefa70379097050fd2caff410a5a287e6c2d30a1d2c":
        "sha256:97f753cea048d151d29bfc09ed08fc9161f206eb44b7bf748a0474d96810be97",
    # and nonneg() passing an unsigned index through as it is (the same five cases, 1 and 2
    # threads: the same to the bit)
    "sha256:2ef25e4b0b3ee86aa94b13d572309792cfcd889254f3fa5adb5ba255e016666e":
        "sha256:97f753cea048d151d29bfc09ed08fc9161f206eb44b7bf748a0474d96810be97",
    # and a stencil's weights divided by their sum only where it is not exactly 1 (the same
    # five cases, 1 and 2 threads: the same to the bit)
    "sha256:83bfb3b23a0d9218487dce22f36c372301dbda7b130c0991e1dd520bba2f4a8f":
        "sha256:97f753cea048d151d29bfc09ed08fc9161f206eb44b7bf748a0474d96810be97",
    # and a listed pair's contact released by one helper too (the same five cases, 1 and 2
    # threads: the same to the bit)
    "sha256:9cb55a14a91b6beb7d83d5eb927f43289a7b575804b4e36636b123c376ce551d":
        "sha256:97f753cea048d151d29bfc09ed08fc9161f206eb44b7bf748a0474d96810be97",
    # and the smoothing's sweeps carrying a row's cells in registers, and the coupled
    # exchange's last k-epsilon step beside the smoothing of the cell values (the same five
    # cases, 1 and 2 threads: the same to the bit)
    "sha256:ceee6cfed8a6b61782b992b4258a1b3dced9bdb269ed5ee4ce6ed58ee58f61ea":
        "sha256:97f753cea048d151d29bfc09ed08fc9161f206eb44b7bf748a0474d96810be97",
    # and the k-epsilon transport's faces computed once for their two cells (the same five
    # cases, 1 and 2 threads: the same to the bit)
    "sha256:b7caf51ba024142cff1b9ef5cc8b308643e62167dd55c690b41c447a12b57b74":
        "sha256:97f753cea048d151d29bfc09ed08fc9161f206eb44b7bf748a0474d96810be97",
    # and the fused exchange's deposit, totals' smoothing and split onto the nodes as two
    # tasks, one per half of the columns (the same five cases, 1 and 2 threads: the same to
    # the bit)
    "sha256:ea76e9b1fda01380291ddbe97cb19189534006432ae10d9a72853339423eeda9":
        "sha256:97f753cea048d151d29bfc09ed08fc9161f206eb44b7bf748a0474d96810be97",
    # and an exchange after a gap (the DEM advanced alone) fused too, the beads' present
    # void fraction first (the same five cases, 1 and 2 threads, and the fused-exchange test
    # over a gap: the same to the bit)
    "sha256:50bac24334477f365a7965071f5bccd36618157125d5d1e08d911736587dc482":
        "sha256:97f753cea048d151d29bfc09ed08fc9161f206eb44b7bf748a0474d96810be97",
    # and the liquid predictor's normal and edge stresses in one parallel loop over the
    # rows, its three rates in another (the same five cases, 1 and 2 threads: the same to
    # the bit)
    "sha256:8e15d7929d5eedaa1cafcc4f51a847120574a79201dda2042035e7c4b7dbcf1e":
        "sha256:97f753cea048d151d29bfc09ed08fc9161f206eb44b7bf748a0474d96810be97",
    # and the predictor's sums beside the projection's right-hand side and the pressure
    # solve (the same five cases, 1 and 2 threads: the same to the bit)
    "sha256:bf2ade05a5fc8ff2b30397f9a1b31d3b535671dc2446c1803f7f965f27dc3ce3":
        "sha256:97f753cea048d151d29bfc09ed08fc9161f206eb44b7bf748a0474d96810be97",
    # and the split onto the nodes' two parts sharing one helper (the same five cases, 1
    # and 2 threads: the same to the bit)
    "sha256:1298d213f796f1deeb417a30c6377010afcff35b9f4f18fc80074c67ffd99f0e":
        "sha256:97f753cea048d151d29bfc09ed08fc9161f206eb44b7bf748a0474d96810be97",
    # and the fused exchange's two-task forms taken on one or two threads only, the
    # kernels' own loops on more (the same five cases, 1 and 2 threads, and the
    # fused-exchange test in both forms: the same to the bit)
    "sha256:16bacdb9a3a877e00d31c12bf64e7b38e052146152f1367906ea10d02fd8140d":
        "sha256:97f753cea048d151d29bfc09ed08fc9161f206eb44b7bf748a0474d96810be97",
    # and the liquid's per-kernel wrappers that the merged loops left unused removed, the
    # beads' pass to the grid one helper for both exchanges (the same five cases, 1 and 2
    # threads: the same to the bit)
    "sha256:8381c6f61d236e99a38b337d9d4d03779c917c3354b5daff99dfe579251d7fca":
        "sha256:97f753cea048d151d29bfc09ed08fc9161f206eb44b7bf748a0474d96810be97",
    # and the Koch-Hill law's code in one module (engine/koch_hill2001.py, each path's
    # evaluation order kept), the held drag's fallback one helper, the pressure solvers'
    # names in fluid/settings.py, the set-up functions cut into parts and the docstrings
    # without their history (coupled, 4-theta-cell, discrete-phase and plain sectors from
    # rest and turning, prescribed swirl at eps 0.52 and 0.7, a coupled accelerator slice
    # in water and at 0.4 Pa s, on 1 and 2 threads: stats.json, the other outputs and the
    # state, the same to the bit)
    "sha256:d06d486a7a2818b4f5d8ac4de1a8a982061088390199145cf6bf727f62ac87e8":
        "sha256:97f753cea048d151d29bfc09ed08fc9161f206eb44b7bf748a0474d96810be97",
    # and the flags that compiled callers passed as constants (compute_forces' step and
    # fuse from finish_step, rebuild's wrap from advance, the exchange's same_eps from the
    # run of intervals, turbulence's on_threads, transport's is_eps, diffuse's totals and
    # column count) passed as typed values, so that numba compiles one kernel for them
    # instead of one per constant, and the liquid's row helpers of stresses and rates
    # called per row instead of inlined (a coupled disc sector on 1 and 2 threads, a plain
    # one and a coupled accelerator sector on 2: stats.json and the other outputs the same
    # to the bit)
    "sha256:4bcf104e8062ac8ba7623c2653ac04d85e7dc25285bb2198e3c2e0a0fe266636":
        "sha256:97f753cea048d151d29bfc09ed08fc9161f206eb44b7bf748a0474d96810be97",
    # one unit-suffix convention (names only; stats.json and a checkpoint of the earlier
    # spelling read with the current names): 17 cases on 1 and 2 threads, stats.json, the
    # other outputs and the state after 200 more steps the same to the bit (three of them,
    # a 0.4 Pa s liquid started turning, stop as unstable at the same step either way)
    "sha256:ccfe999eeb245cff904badce12eca5351083bf878c6f2247a5f5f24bda20361f":
        "sha256:97f753cea048d151d29bfc09ed08fc9161f206eb44b7bf748a0474d96810be97",
    # the wet restitution per contact by name (off by default: the same results to the bit
    # as the sources before, ccfe999e...)
    "sha256:24fc121abc14cb39d48cb470a8c68ad789d2018fc52ae82b2a207c4bd2fe242a":
        "sha256:97f753cea048d151d29bfc09ed08fc9161f206eb44b7bf748a0474d96810be97",
    # the wet restitution's damping ratios from params.damping_beta_of, the material's one
    # formula (the same results to the bit)
    "sha256:468c540caa3e8513809a96a86e4780d015288f7cae47c329ced1edbc5aaead9d":
        "sha256:97f753cea048d151d29bfc09ed08fc9161f206eb44b7bf748a0474d96810be97",
    "sha256:4e1132db37500f254fa6463996054d53ba92e8018fecc9b47a3f0538e65a690e":
        "sha256:97f753cea048d151d29bfc09ed08fc9161f206eb44b7bf748a0474d96810be97",
    # and the run's docstring naming collision_maps.npz among its outputs (written by the
    # maps' module, which is no kernel source; no code changed)
    "sha256:2b1eeb88ae4daf6f9431d5561622269d7e224356f97b1f1eefb9f0489af8ddd1":
        "sha256:97f753cea048d151d29bfc09ed08fc9161f206eb44b7bf748a0474d96810be97",
    # and a short coupled run on a cold kernel cache taking the exchange by calls instead of
    # the fused one (first_compile.fused_exchange; the short coupled disc sector's outputs
    # the same to the bit by either, the fused-exchange tests in both forms)
    "sha256:2ec323aa6e6d5813793e79d48ebfe53c062ba71a48e06396d8e608ade0800fb1":
        "sha256:97f753cea048d151d29bfc09ed08fc9161f206eb44b7bf748a0474d96810be97",
    # and the coupling's beads' side on the GPU where the DEM steps there
    # (coupling.gpu_exchange; the CPU's path unchanged: the coupled disc sector on 1 and 2
    # threads, one with 4 theta cells and theta_fft, and the accelerator slice give the
    # same outputs to the bit; then a docstring reworded, no code changed)
    "sha256:32e599996135f5179a549a20ef8809faea0e19fe6c11219bccf5e592d028521c":
        "sha256:97f753cea048d151d29bfc09ed08fc9161f206eb44b7bf748a0474d96810be97",
    # and make_simulation's docstring saying where the GPU's coupled exchange runs (no
    # code changed)
    "sha256:279ba3777b182df7026a85cd23473e36fd6b75b7223b62b5d56a2b9888fb9aab":
        "sha256:97f753cea048d151d29bfc09ed08fc9161f206eb44b7bf748a0474d96810be97",
    # and each bead's part of the exchange's beads_in and bead_forces as an inlined
    # function that the GPU's kernels share (the coupled disc sector on 1 and 2 threads,
    # primed, with 4 theta cells and theta_fft, and the accelerator slice give the same
    # outputs to the bit)
    "sha256:a3596a93f9f0e1c6e312586030a9f2999e1c4ea3776e684517be5798b2957369":
        "sha256:97f753cea048d151d29bfc09ed08fc9161f206eb44b7bf748a0474d96810be97",
    # and the GPU's stencils copied to the host when the beads' side leaves the GPU (a
    # branch that runs only where the DEM steps on a GPU; the CPU's runs never reach it)
    "sha256:f718db700a5b547d693d3f0d8aaac512884f6e2b15e0da3d0c7ad6b8b519f316":
        "sha256:97f753cea048d151d29bfc09ed08fc9161f206eb44b7bf748a0474d96810be97",
    # and a bead's stencil with its cylindrical velocity, and the cell values read back at
    # it, as inlined functions (projection.bead_cyl, at_bead, at_bead3) that the exchange and
    # the discrete phase model's drag share (the coupled disc sector on 1 and 2 threads,
    # primed, with 4 theta cells and theta_fft, the accelerator slice, and seed 002's
    # discrete phase model with Koch-Hill and Schiller-Naumann drag give the same outputs
    # to the bit)
    "sha256:0ce8364e820e5394da6b0dd39c382cdad5204871baf995d583a7d0564e137867":
        "sha256:97f753cea048d151d29bfc09ed08fc9161f206eb44b7bf748a0474d96810be97",
    # and the bead-wall friction and rolling friction as parameter entries of their own,
    # the bead-bead values where a scene names none (the plain disc sector on 1 and 2
    # threads, the coupled disc sector on 1 and 2 threads, the accelerator slice, and seed
    # 002's discrete phase model with Koch-Hill and Schiller-Naumann drag give the same
    # outputs to the bit); and a run's summary line for an accelerator slice without liquid
    "sha256:ff37c85dee21753cc551979310020cd098213e8088bd9d7f06b99de03f4a09e2":
        "sha256:97f753cea048d151d29bfc09ed08fc9161f206eb44b7bf748a0474d96810be97",
    # and the first bead layer's distance from the disc face read from
    # analysis.flow_structure.FIRST_LAYER_DIAMETERS (0.75, the literal it replaces) in the
    # run's statistics (a plain disc sector gives the same outputs to the bit)
    "sha256:59694c5e4e2752822505257f14a45f8d10106172c5a73c4a16744fa0d41b8c48":
        "sha256:97f753cea048d151d29bfc09ed08fc9161f206eb44b7bf748a0474d96810be97",
    # and model A's beads' viscous-stress force as an option of its own
    # ([fluid.coupled] bead_stress_force, fluid.anderson_jackson1967; off by default: the
    # coupled disc sector on 1 and 2 threads, with direct_lu and with 4 theta cells, the plain
    # disc sector, the accelerator slice by model B and A and by the discrete phase model give
    # the same outputs to the bit, the new sources' kernels compiled afresh)
    "sha256:7ab47fda7f5e5a82dbddfe4d09b663cffa6a9670eb3a100726a39c851bf9c682":
        "sha256:97f753cea048d151d29bfc09ed08fc9161f206eb44b7bf748a0474d96810be97",
    # and the smoothing on the GPU where the DEM steps there (coupling.gpu_exchange; the
    # CPU's path unchanged: the coupled disc sector on 1 and 2 threads, primed, with 4 theta
    # cells and theta_fft, the plain disc sector and the accelerator slice give the same
    # outputs to the bit, the new sources' kernels compiled afresh)
    "sha256:92ab6ca92d467bfd409679c5f7effb202c408a1c621c7a7e2d10e47f35ac70b7":
        "sha256:97f753cea048d151d29bfc09ed08fc9161f206eb44b7bf748a0474d96810be97",
}


#: Name of a cache entry's folder: its table's key (sha256, hex).
ENTRY_NAME = re.compile(r"[0-9a-f]{64}")
#: Folder of the cache that holds finished grid points (:class:`PointStore`).
POINTS_DIR = "points"


def dem_kernel_version() -> str:
    """sha256 over the labels and source files of :data:`KERNEL_MODULES` (read, not
    imported: no numba), or the version that :data:`SAME_DEM_AS` gives for it (the same
    results to the bit), or the version that the evidence of
    :mod:`millfmu.dem.tables.equivalence` accepts it as (a change of round-off only, its
    statistics within the spread of the version's own realizations)."""
    # SAME_DEM_AS may name a version or the source hash of an accepted round-off change
    # (sources the same to the bit as those), which the evidence then resolves
    src = kernel_source_hash()
    h = SAME_DEM_AS.get(src, src)
    from .equivalence import accepted_versions

    return accepted_versions().get(h, h)


def kernel_source_hash() -> str:
    """sha256 over the labels and source files of :data:`KERNEL_MODULES`."""
    h = hashlib.sha256()
    for label, mod in KERNEL_MODULES.items():
        spec = importlib.util.find_spec(mod)
        if spec is None or spec.origin is None:
            raise TableError(f"DEM kernel version: module {mod} not found")
        h.update(label.encode() + b"\0" + Path(spec.origin).read_bytes() + b"\0")
    return "sha256:" + h.hexdigest()


def default_cache_dir() -> Path:
    """The tables cache folder: $MILLFMU_CACHE_DIR, else $XDG_CACHE_HOME/millfmu/tables,
    else ~/.cache/millfmu/tables."""
    env = os.environ.get("MILLFMU_CACHE_DIR")
    if env:
        return Path(env).expanduser()
    xdg = os.environ.get("XDG_CACHE_HOME")
    base = Path(xdg).expanduser() if xdg else Path.home() / ".cache"
    return base / "millfmu" / "tables"


def resolve_cache_dir(cache_dir=None) -> Path:
    """``cache_dir`` if given (CLI --cache-dir), else :func:`default_cache_dir`."""
    return Path(cache_dir).expanduser() if cache_dir else default_cache_dir()


@contextlib.contextmanager
def _locked(path: Path):
    with open(path, "a+") as fh:
        fcntl.flock(fh.fileno(), fcntl.LOCK_EX)
        try:
            yield
        finally:
            fcntl.flock(fh.fileno(), fcntl.LOCK_UN)


def entry_dir(spec: TableSpec, cache_dir=None) -> Path:
    return resolve_cache_dir(cache_dir) / spec.key()


def load_cached(spec: TableSpec, cache_dir=None) -> Table | None:
    """The cached table of ``spec`` if its entry passes every check, else None; an entry of
    the earlier format (its own key) is read with the current names."""
    for d in (entry_dir(spec, cache_dir), resolve_cache_dir(cache_dir) / spec.earlier_key()):
        if not d.exists():
            continue
        try:
            return read_table(d, expect_key=spec.key(), expect_kernel=spec.kernel_version)
        except TableError:
            continue
    return None


def seed_tables(spec: TableSpec) -> list:
    """The shipped tables whose points a build of ``spec`` can reuse: same builder, kernel
    version and DEM scene (a point's key holds the scene at the point, so only equal scenes
    share points). Read without the DEM; a table that cannot be read is skipped."""
    from ...stress_tables.table import SHIPPED_TABLES, read_table_ref

    out = []
    for name in SHIPPED_TABLES:
        try:
            t = read_table_ref(name)
            other = t.spec()
        except (TableError, OSError):
            continue
        if (other.builder_id, other.kernel_version, other.scene) == (spec.builder_id, spec.kernel_version, spec.scene):
            out.append(t)
    return out


def get_table(spec: TableSpec, builder: Callable, cache_dir=None, force: bool = False,
              log: Callable[[str], None] | None = None, seed_from=(),
              manifest_extra: dict | None = None, **run_kw) -> Table:
    """The table of ``spec``: from the cache if its entry verifies, else built and cached.

    Concurrent callers serialize on ``<cache>/<key>.lock`` (fcntl.flock); the second finds
    the first one's entry. A new entry is written into a temporary folder in the cache and
    renamed into place, so readers see either no entry or a complete one; an entry that
    fails verification is replaced. Finished grid points are kept in ``<cache>/points``
    (:class:`~.build.PointStore`): a build that was cut off, or a damaged entry, is
    completed from them, running only the points that are missing. Before a build the store
    is seeded with the points of ``seed_from`` (tables, e.g. the one being extended) and of
    the shipped tables of the same DEM scene and kernel (:func:`seed_tables`), so that a new
    operating point costs its own runs only. ``force`` rebuilds even a good entry and runs
    every point again. ``manifest_extra``: entries added to the new table's manifest.
    """
    root = resolve_cache_dir(cache_dir)
    key = spec.key()
    if not force:
        t = load_cached(spec, root)
        if t is not None:
            return t
    root.mkdir(parents=True, exist_ok=True)
    with _locked(root / f"{key}.lock"):
        if not force:
            t = load_cached(spec, root)  # built by another process while we waited
            if t is not None:
                return t
        final = root / key
        if final.exists() and log is not None:
            try:
                read_table(final, expect_key=key, expect_kernel=spec.kernel_version)
            except TableError as e:
                log(f"rebuilding cache entry {key[:12]}: {e}")
        store = run_kw.setdefault("point_store", PointStore(root / POINTS_DIR, reuse=not force))
        if store is not None and store.reuse:
            seeds = (*seed_from, *seed_tables(spec))
            seeded = sum(store.seed(t) for t in seeds)
            if seeded and log is not None:
                log(f"point store: {seeded} point(s) taken from finished tables")
            if "seconds_per_cost" not in run_kw:
                # the time left of a build over a finished table's scene and kernel, from the
                # time its points took (before this build's first point finishes)
                spc = [x for x in (seconds_per_cost(t, builder) for t in seeds) if x is not None]
                if spc:
                    run_kw["seconds_per_cost"] = spc[0]
        if store is not None and hasattr(builder, "with_states"):
            # the DEM keeps each point's settled state beside its result, and may start a
            # new point from one of those there now (warm_start; after the calibration
            # above, which costs the finished points by their own starts)
            builder = builder.with_states(store.folder, reuse=store.reuse)
        table = build_table(spec, builder, **run_kw)
        tmp = Path(tempfile.mkdtemp(prefix=f".tmp-{key[:16]}-", dir=root))
        try:
            table.save(tmp, manifest_for(spec, table, extra=manifest_extra or None,
                                         work_precision=getattr(builder, "work_precision", None)))
            if final.exists():
                trash = Path(tempfile.mkdtemp(prefix=f".old-{key[:16]}-", dir=root))
                os.rename(final, trash / "entry")
                shutil.rmtree(trash, ignore_errors=True)
            os.rename(tmp, final)
        except BaseException:
            shutil.rmtree(tmp, ignore_errors=True)
            raise
        fsync_dir(root)
        return read_table(final, expect_key=key, expect_kernel=spec.kernel_version)


def cache_entries(cache_dir=None, kernel_version: str | None = None) -> list[dict]:
    """Every entry of the cache with its state: ``ok``, ``stale`` (older kernel version or
    format) or ``bad`` (fails a check), the reason, scene name, grid shape and size [bytes]."""
    root = resolve_cache_dir(cache_dir)
    out = []
    if not root.exists():
        return out
    if not root.is_dir():
        raise TableError(f"tables cache {root}: not a folder; give the cache's folder (--cache-dir, "
                         "$MILLFMU_CACHE_DIR)")
    kv = kernel_version if kernel_version is not None else dem_kernel_version()
    # Only folders named as the cache names its entries: another folder (a --cache-dir that
    # names the wrong folder) is neither listed nor removed.
    for d in sorted(p for p in root.iterdir() if p.is_dir() and ENTRY_NAME.fullmatch(p.name)):
        info = {"key": d.name, "path": str(d),
                "bytes": sum(f.stat().st_size for f in d.iterdir() if f.is_file())}
        try:
            t = read_table(d, expect_key=d.name)
            m = t.manifest
            info.update(scene=m["scene"].get("name", "?"), shape=list(t.shape),
                        axes=list(t.axes), builder=m["builder"])
            if m["builder"] == DEM_BUILDER_ID and m["kernel_version"] != kv:
                info.update(state="stale", reason="built with DEM kernel version "
                            f"{m['kernel_version'][:19]}..., current {kv[:19]}...")
            else:
                info.update(state="ok", reason="")
        except TableError as e:
            info.update(state="stale" if "stale" in str(e) else "bad", reason=str(e))
        out.append(info)
    return out


def clear_cache(cache_dir=None, only_not_ok: bool = False,
                kernel_version: str | None = None) -> list[str]:
    """Remove cache entries (all, or only stale and bad ones) and leftover temporary
    folders; returns the removed keys. Takes each entry's lock so that no build is cut."""
    root = resolve_cache_dir(cache_dir)
    removed = []
    if not root.exists():
        return removed
    for e in cache_entries(root, kernel_version):
        if only_not_ok and e["state"] == "ok":
            continue
        with _locked(root / f"{e['key']}.lock"):
            shutil.rmtree(e["path"], ignore_errors=True)
        (root / f"{e['key']}.lock").unlink(missing_ok=True)
        removed.append(e["key"])
    removed += _clear_points(root / POINTS_DIR, only_not_ok,
                             kernel_version if kernel_version is not None
                             else dem_kernel_version())
    for p in root.glob(".tmp-*"):
        key16 = p.name[5:21]
        locks = list(root.glob(f"{key16}*.lock"))
        if not locks:
            shutil.rmtree(p, ignore_errors=True)
            continue
        with open(locks[0], "a+") as fh:  # skip folders of a build in progress
            try:
                fcntl.flock(fh.fileno(), fcntl.LOCK_EX | fcntl.LOCK_NB)
            except BlockingIOError:
                continue
            shutil.rmtree(p, ignore_errors=True)
            fcntl.flock(fh.fileno(), fcntl.LOCK_UN)
    return removed


def _clear_states(folder: Path, only_stale: bool, kernel_version: str) -> list[str]:
    """Remove the points' settled states (warm_start): all, or those of another DEM kernel
    version or layout; returns 'points/NAME' for each removed file."""
    from .state_files import STATE_SUFFIX, WarmStartError, read_meta

    removed = []
    for f in sorted(folder.glob("*" + STATE_SUFFIX)):
        if only_stale:
            try:
                if read_meta(f).get("kernel_version") == kernel_version:
                    continue
            except WarmStartError:
                pass
        f.unlink(missing_ok=True)
        removed.append(f"{POINTS_DIR}/{f.name}")
    return removed


def _clear_points(folder: Path, only_stale: bool, kernel_version: str) -> list[str]:
    """Remove finished grid points (all, or those of another DEM kernel version or that
    do not parse); returns 'points/KEY' for each removed file."""
    removed = []
    if not folder.is_dir():
        return removed
    for f in sorted(folder.glob("*.json")):
        if only_stale:
            try:
                kc = json.loads(f.read_text())["key_content"]
                if kc["format"] in (FORMAT_VERSION, EARLIER_FORMAT) and (
                        kc["builder"] != DEM_BUILDER_ID or kc["kernel_version"] == kernel_version):
                    continue
            except (OSError, ValueError, KeyError, TypeError):
                pass
        f.unlink(missing_ok=True)
        removed.append(f"{POINTS_DIR}/{f.stem}")
    removed += _clear_states(folder, only_stale, kernel_version)
    from .point_folders import clear_running

    removed += [f"{POINTS_DIR}/{r}" for r in clear_running(folder, only_stale, kernel_version)]
    # Temporary files of a point being written live for milliseconds; one older than an
    # hour was left by a killed build.
    for f in [*folder.glob(".tmp-point-*"), *folder.glob(".tmp-state-*")]:
        try:
            if time.time() - f.stat().st_mtime > 3600.0:
                f.unlink()
        except OSError:
            pass
    return removed
