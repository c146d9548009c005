# The two commands of the README's quick start, and the pieces they use.
#   make venv    set up .venv with the clone installed in editable mode (the
#                C extensions built beside the sources; docs/development.md)
#   make lint    ruff and mypy (settings in pyproject.toml)
#   make reproduce  set up .venv, build and install pyrhonn, reproduce the
#                   paper's Tables 1-6 (pyrhonn reproduce all) into reproduce-out/
#   make bench   set up .venv, build and install pyrhonn, run the benchmarks
#   make docs    set up .venv, build the documentation site into site/ (mkdocs
#                --strict: a warning or a broken link fails it)
#   make test    set up .venv, lint, build the docs, run the Python tests, then again with every
#                CPU busy (stress-ng; SKIP_LOADED=1 skips it), then the C tests
#                under CTest (plain, then with AddressSanitizer + UBSan), then
#                the SocketCAN tests inside a VM with vcan0 (SKIP_VM=1 skips it; the
#                runners they start are built on the host first)
PYTHON ?= python3
VENV   ?= .venv
BUILD  ?= build
JOBS   ?= 2
# pytest workers (pytest-xdist): one per CPU; a module's tests stay on one worker, so its fixtures are
# built once. PYTEST_WORKERS=0 runs the tests in this process, one after another.
PYTEST_WORKERS ?= $(shell nproc)
PYTEST_XDIST = -n $(PYTEST_WORKERS) --dist loadscope

.PHONY: venv lint reproduce bench docs test test-python test-python-loaded test-c test-c-sanitize test-fuzz test-vm clean

venv:
	test -x $(VENV)/bin/python || $(PYTHON) -m venv $(VENV)
	$(VENV)/bin/python -m pip install --quiet --upgrade pip
	$(VENV)/bin/python -m pip install --quiet -e ".[test]" cmake

# Run before every other tier of `make test`: a lint error fails it early.
# Alone it uses the .venv that `make venv` set up (without installing again).
lint:
	@test -x $(VENV)/bin/ruff -a -x $(VENV)/bin/mypy || { echo "lint: no ruff and mypy in $(VENV): run make venv"; exit 1; }
	$(VENV)/bin/ruff check .
	$(VENV)/bin/mypy

reproduce: venv
	$(VENV)/bin/pyrhonn reproduce all --out reproduce-out

bench: venv
	$(VENV)/bin/python bench/bench_identifier.py
	$(VENV)/bin/python bench/bench_cortex_m4.py
	$(VENV)/bin/python bench/bench_linux_runner.py
	$(VENV)/bin/python bench/bench_hil_udp.py --fifo 50 --cpus 0,1
	$(VENV)/bin/python bench/bench_writes.py
	$(VENV)/bin/python bench/bench_core_vs_dense.py
	$(VENV)/bin/python bench/bench_real_data.py

test: venv lint docs test-python test-python-loaded test-c test-c-sanitize test-fuzz test-vm

# The site's reference pages are generated from the installed package
# (docs_hooks.py): the CLI from its parser, the config keys, the C headers.
docs: venv
	NO_MKDOCS_2_WARNING=1 $(VENV)/bin/mkdocs build --strict --quiet --site-dir site

# Run from tests/, as a user's program runs from its own folder: the tests
# import the package that .venv holds (the clone, installed in editable mode).
test-python:
	cd tests && ../$(VENV)/bin/python -m pytest -q -p no:cacheprovider $(PYTEST_XDIST) .

# The Python tests once more with every CPU busy: a user's machine is rarely
# idle, and a functional test must pass on a loaded one (timing belongs in
# bench/). stress-ng runs one CPU hog per CPU for the whole run and is stopped
# whatever happens (trap; its --timeout is the backstop); the run's duration
# and its slowest tests are printed. Run as root without stress-ng, it is
# installed (Debian); else the target fails unless SKIP_LOADED=1.
STRESS_NG ?= stress-ng
test-python-loaded:
ifeq ($(SKIP_LOADED),1)
	@echo "test-python-loaded: skipped (SKIP_LOADED=1)"
else
	@command -v $(STRESS_NG) >/dev/null || { [ "$$(id -u)" = 0 ] && command -v apt-get >/dev/null && \
	  DEBIAN_FRONTEND=noninteractive apt-get install -y -o DPkg::Lock::Timeout=900 --no-install-recommends \
	  stress-ng >/dev/null; } || { echo "test-python-loaded: no $(STRESS_NG) (Debian: apt-get install stress-ng;" \
	  "SKIP_LOADED=1 skips this run)"; exit 1; }
	cd tests && { $(STRESS_NG) --cpu "$$(nproc)" --timeout 3600 --quiet & hog=$$!; \
	  trap 'kill $$hog 2>/dev/null; wait $$hog 2>/dev/null' EXIT INT TERM HUP; start=$$(date +%s); \
	  $(abspath $(VENV))/bin/python -m pytest -q -p no:cacheprovider $(PYTEST_XDIST) --durations=15 .; rc=$$?; \
	  echo "test-python-loaded: $$(( $$(date +%s) - start )) s with $$(nproc) CPUs busy (stress-ng)"; exit $$rc; }
endif

test-c:
	$(VENV)/bin/cmake -S . -B $(BUILD)/release -DCMAKE_BUILD_TYPE=Release -DRHONN_WERROR=ON
	$(VENV)/bin/cmake --build $(BUILD)/release -j $(JOBS)
	$(VENV)/bin/ctest --test-dir $(BUILD)/release --output-on-failure

test-c-sanitize:
	$(VENV)/bin/cmake -S . -B $(BUILD)/sanitize -DCMAKE_BUILD_TYPE=Debug -DRHONN_SANITIZE=ON -DRHONN_WERROR=ON
	$(VENV)/bin/cmake --build $(BUILD)/sanitize -j $(JOBS)
	$(VENV)/bin/ctest --test-dir $(BUILD)/sanitize --output-on-failure

# libFuzzer, with ASan and UBSan, each target from its own seed corpus:
# - fuzz-frame: the firmware's frame-receive entry for FUZZ_SECONDS; a crash, a
#   sanitizer report or a rejected frame that changes the filter fails the run
#   (firmware_sim/fuzz/);
# - fuzz-xcp: the XCP slave's command entry (firmware_sim/fuzz/fuzz_xcp.c) for
#   FUZZ_XCP_SECONDS; a command that moves the identifier, a calibration write
#   without the key, a byte changed outside the two regions fails the run;
# - fuzz-udp: the runner's udp_multicast codec for FUZZ_UDP_SECONDS, seeded
#   with python-can's own datagrams; an accepted datagram must re-encode to
#   itself;
# - fuzz-core-f32/f64: the core (csrc/fuzz/fuzz_core.c); a committed
#   covariance that is not positive definite, an update with s < R or a refused
#   call that changed the filter fails the run;
# - fuzz-wide-f32/f64: rhonn_run_wide against rhonn_run, and steps in the lanes
#   against rhonn_step (csrc/fuzz/fuzz_wide.c); any difference fails the run;
# - fuzz-pop-f32/f64: each member of rhonn_run_population against its own
#   rhonn_run (csrc/fuzz/fuzz_population.c); any difference fails the run.
# Each is a make target of its own (make fuzz-core-f64 FUZZ_CORE_SECONDS=600).
CLANG ?= clang-14
FUZZ_CFLAGS = -g -O1 -fsanitize=fuzzer,address,undefined -fno-sanitize-recover=all
FUZZ_SECONDS ?= 45
FUZZ_UDP_SECONDS ?= 20
FUZZ_XCP_SECONDS ?= 15
# the core's public API (csrc/fuzz/fuzz_core.c), per precision; 600 for a real campaign
FUZZ_CORE_SECONDS ?= 30
# one identifier's neurons side by side against rhonn_run and rhonn_step, per precision
FUZZ_WIDE_SECONDS ?= 20
FUZZ_POP_SECONDS ?= 20
FW_FLAGS = -std=c99 -ffp-contract=off -DRHONN_SINGLE -Icsrc/include -Ifirmware_sim/app \
	-Ifirmware_sim/generated -Ifirmware_sim/config
FW_SOURCES = firmware_sim/app/fw_app.c firmware_sim/app/fw_protocol.c firmware_sim/app/fw_hal_mem.c \
	firmware_sim/app/fw_secoc.c firmware_sim/app/fw_aes_cmac.c firmware_sim/app/fw_xcp.c \
	firmware_sim/generated/rhonn_id.c csrc/src/rhonn.c
# The fuzz targets run two at a time (FUZZ_JOBS, one per CPU: each libFuzzer
# run is one process), every one for its own time; each prints its last lines
# when it ends (--output-sync keeps them together).
FUZZ_JOBS ?= 2
FUZZ_TARGETS = fuzz-frame fuzz-xcp fuzz-udp fuzz-core-f32 fuzz-core-f64 fuzz-wide-f32 fuzz-wide-f64 fuzz-pop-f32 fuzz-pop-f64
.PHONY: $(FUZZ_TARGETS)
test-fuzz:
	$(MAKE) --no-print-directory --output-sync=target -j $(FUZZ_JOBS) $(FUZZ_TARGETS)

fuzz-frame:
	mkdir -p $(BUILD)/fuzz/corpus
	$(CLANG) $(FUZZ_CFLAGS) $(FW_FLAGS) \
	  firmware_sim/fuzz/fuzz_on_frame.c $(FW_SOURCES) -o $(BUILD)/fuzz/fuzz_on_frame
	cc -Wall -Wextra $(FW_FLAGS) firmware_sim/fuzz/make_seeds.c firmware_sim/generated/rhonn_id.c \
	  -o $(BUILD)/fuzz/make_seeds
	$(BUILD)/fuzz/make_seeds $(BUILD)/fuzz/corpus
	$(BUILD)/fuzz/fuzz_on_frame -max_total_time=$(FUZZ_SECONDS) -print_final_stats=1 \
	  -artifact_prefix=$(BUILD)/fuzz/ $(BUILD)/fuzz/corpus > $(BUILD)/fuzz/log 2>&1; \
	  rc=$$?; tail -n 8 $(BUILD)/fuzz/log; exit $$rc

fuzz-xcp:
	mkdir -p $(BUILD)/fuzz/xcp-corpus
	$(CLANG) $(FUZZ_CFLAGS) $(FW_FLAGS) \
	  firmware_sim/fuzz/fuzz_xcp.c $(FW_SOURCES) -o $(BUILD)/fuzz/fuzz_xcp
	printf '\000\002\377\000\370\000\371\000\360\004abcd\003\010\364\004\000\000\000\000\000\000' \
	  > $(BUILD)/fuzz/xcp-corpus/seed0
	$(BUILD)/fuzz/fuzz_xcp -max_total_time=$(FUZZ_XCP_SECONDS) -print_final_stats=1 \
	  -artifact_prefix=$(BUILD)/fuzz/xcp- $(BUILD)/fuzz/xcp-corpus > $(BUILD)/fuzz/xcp-log 2>&1; \
	  rc=$$?; tail -n 8 $(BUILD)/fuzz/xcp-log; exit $$rc

fuzz-udp:
	mkdir -p $(BUILD)/fuzz/udp-corpus
	$(CLANG) $(FUZZ_CFLAGS) -std=c99 \
	  firmware_sim/linux/fuzz_udp_can.c firmware_sim/linux/udp_can.c -o $(BUILD)/fuzz/fuzz_udp_can
	$(VENV)/bin/python -c 'import can, sys; from can.interfaces.udp_multicast.utils import pack_message as p; \
	  [open(f"{sys.argv[1]}/seed{i}", "wb").write(p(m)) for i, m in enumerate([can.Message(arbitration_id=0x101, \
	  data=bytes(20), is_fd=True, is_extended_id=False), can.Message(arbitration_id=0x1ABCDEF, data=b"\x01\x02"), \
	  can.Message(timestamp=1.5, arbitration_id=0x7FF, data=bytes(range(64)), is_fd=True, bitrate_switch=True, \
	  is_extended_id=False, channel="vcan0")])]' $(BUILD)/fuzz/udp-corpus
	$(BUILD)/fuzz/fuzz_udp_can -max_total_time=$(FUZZ_UDP_SECONDS) -print_final_stats=1 \
	  -artifact_prefix=$(BUILD)/fuzz/udp- $(BUILD)/fuzz/udp-corpus > $(BUILD)/fuzz/udp-log 2>&1; \
	  rc=$$?; tail -n 8 $(BUILD)/fuzz/udp-log; exit $$rc

# One core fuzz target in one precision: $(call fuzz_core,NAME,PRECISION,SOURCES,SECONDS)
# builds $(BUILD)/fuzz/fuzz_NAME_PRECISION and runs it on its own corpus.
define fuzz_core
	mkdir -p $(BUILD)/fuzz/$(1)-$(2)-corpus
	$(CLANG) $(FUZZ_CFLAGS) -std=c99 -ffp-contract=off \
	  $(if $(filter f32,$(2)),-DRHONN_SINGLE) -Icsrc/include $(3) -o $(BUILD)/fuzz/fuzz_$(1)_$(2)
	$(BUILD)/fuzz/fuzz_$(1)_$(2) -max_total_time=$(4) -print_final_stats=1 \
	  -artifact_prefix=$(BUILD)/fuzz/$(1)-$(2)- $(BUILD)/fuzz/$(1)-$(2)-corpus > $(BUILD)/fuzz/$(1)-$(2)-log 2>&1; \
	  rc=$$?; tail -n 4 $(BUILD)/fuzz/$(1)-$(2)-log; exit $$rc
endef
fuzz-core-f32 fuzz-core-f64: fuzz-core-%:
	$(call fuzz_core,core,$*,csrc/fuzz/fuzz_core.c csrc/src/rhonn.c,$(FUZZ_CORE_SECONDS))
fuzz-wide-f32 fuzz-wide-f64: fuzz-wide-%:
	$(call fuzz_core,wide,$*,csrc/fuzz/fuzz_wide.c csrc/src/rhonn.c csrc/src/rhonn_population.c,$(FUZZ_WIDE_SECONDS))
fuzz-pop-f32 fuzz-pop-f64: fuzz-pop-%:
	$(call fuzz_core,population,$*,csrc/fuzz/fuzz_population.c csrc/src/rhonn.c csrc/src/rhonn_population.c,$(FUZZ_POP_SECONDS))

# This kernel may have no CAN: the vcan-marked tests run in a QEMU VM with
# the host's userspace (hil/vm/run_in_vm.py installs what it needs).
# The VM runs only the files that hold vcan tests, found here on the host:
# collecting every test module under software emulation took most of the
# VM's time.
test-vm:
ifeq ($(SKIP_VM),1)
	@echo "test-vm: skipped (SKIP_VM=1)"
else
	files=$$(cd tests && ../$(VENV)/bin/python -m pytest -q --collect-only -m vcan -p no:cacheprovider . \
	  | sed -n 's|^tests/||; s|::.*||p' | sort -u | tr '\n' ' '); \
	  [ -n "$$files" ] || { echo "test-vm: no vcan tests collected"; exit 1; }; \
	  echo "test-vm: $$files"; \
	  $(VENV)/bin/python tests/test_vcan_identifier.py $(BUILD)/vm/identifier >/dev/null && \
	  python3 hil/vm/run_in_vm.py --out $(BUILD)/vm --venv $(BUILD)/virtme-venv -- \
	    sh -c "cd tests && RHONN_RUNNER=$(abspath $(BUILD))/release/firmware_sim/rhonn_runner \
	      PYRHONN_VM_IDENTIFIER=$(abspath $(BUILD))/vm/identifier \
	      ../$(VENV)/bin/python -m pytest -q -p no:cacheprovider -m vcan $$files"
endif

clean:
	rm -rf $(BUILD) $(VENV) pyrhonn/_rhonn_*.so pyrhonn/_rhonn_*.c pyrhonn/_rhonn_*.o pyrhonn/_fwapp*.so pyrhonn/_fwapp.c pyrhonn/_fwapp.o pyrhonn/_csvtext*.so pyrhonn/_csvtext.c pyrhonn/_csvtext.o
