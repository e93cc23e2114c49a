# handrig: `make demo` and `make test` set up .venv as needed, then run.
PYTHON ?= $(shell command -v python3.11 || command -v python3)
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed

.PHONY: demo test lint bench clean render-deps browser-deps orca-core ltc-deps

# Re-install only when pyproject.toml is newer than the last install.
$(STAMP): pyproject.toml setup.py sim/_dxl_c.c
	@test -x $(BIN)/python || $(PYTHON) -m venv $(VENV)
	@$(BIN)/python -m pip install --quiet --upgrade pip
	@$(BIN)/python -m pip install --quiet -e '.[dev]'
	@touch $(STAMP)

demo: $(STAMP)
	$(BIN)/handrig demo

# Three pytest runs side by side (tests/conftest.py says which test goes where): the
# compute-only tests at nice 19, the patient end-to-end ones two at a time at nice 10
# (pytest-xdist, a test file per worker), and the realtime ones one at a time in the
# foreground, first in line for the CPU; the other two reports follow the realtime one's.
test: $(STAMP)
	@clog=$$(mktemp); plog=$$(mktemp); \
	nice -n 19 $(BIN)/python -m pytest -q -p no:cacheprovider -m compute_only >"$$clog" 2>&1 & cpid=$$!; \
	nice -n 10 $(BIN)/python -m pytest -q -p no:cacheprovider -m patient -n 2 --dist loadfile >"$$plog" 2>&1 & ppid=$$!; \
	trap 'kill $$cpid $$ppid 2>/dev/null; rm -f "$$clog" "$$plog"; exit 130' INT TERM HUP; \
	$(BIN)/python -m pytest -q -m "not compute_only and not patient"; rt=$$?; \
	wait $$ppid; pt=$$?; wait $$cpid; ct=$$?; \
	echo "== the patient end-to-end tests, run beside them at nice 10 (pytest -m patient) =="; \
	cat "$$plog"; \
	echo "== the compute-only tests, run beside them at nice 19 (pytest -m compute_only) =="; \
	cat "$$clog"; rm -f "$$clog" "$$plog"; \
	test $$rt -eq 0 && test $$pt -eq 0 && test $$ct -eq 0

lint: $(STAMP)
	$(BIN)/ruff check .
	$(BIN)/mypy

bench: $(STAMP)
	$(BIN)/python -m bench

clean:
	rm -rf $(VENV) $(ORCA_VENV) build *.egg-info .pytest_cache .mypy_cache .ruff_cache

# orca_core, the ORCA hand's own driver (PyPI, MIT), in a venv of its own: it pins
# dynamixel-sdk < 4 where handrig needs >= 4.1. tests/sim/test_orca_core_client.py runs
# its scan, calibration and init against `handrig sim-bus --rig orca` (skipped without it).
ORCA_VENV := .venv-orca
ORCA_CORE ?= orca_core==0.12.0
orca-core: $(ORCA_VENV)/.installed
$(ORCA_VENV)/.installed:
	@test -x $(ORCA_VENV)/bin/python || $(PYTHON) -m venv $(ORCA_VENV)
	@$(ORCA_VENV)/bin/python -m pip install --quiet '$(ORCA_CORE)'
	@touch $@

# LeRobot beside handrig in .venv: the [lerobot] extra (setup.py), which names LeRobot and
# the two plugin distributions LeRobot discovers by name (plugins/: lerobot_teleoperator_handrig,
# lerobot_robot_handrig; docs/lerobot.md): lerobot-record, -replay and -teleoperate then
# find handrig_glove, handrig_leap and handrig_orca, and tests/handrig/app/lerobot run
# instead of skipping. Downloads torch (LeRobot 0.4 allows < 2.11: PyPI's CUDA build).
# pip installs the plugins as copies: a change under plugins/ is installed again here.
LEROBOT_STAMP := $(VENV)/.lerobot-installed
LEROBOT_PLUGINS := plugins/lerobot_teleoperator_handrig plugins/lerobot_robot_handrig
.PHONY: lerobot-deps
lerobot-deps: $(LEROBOT_STAMP)
$(LEROBOT_STAMP): $(STAMP) $(foreach p,$(LEROBOT_PLUGINS),$(p)/pyproject.toml $(wildcard $(p)/lerobot_*/*.py))
	$(BIN)/python -m pip install --quiet -e '.[dev,lerobot]'
	@touch $@

# Offscreen rendering (handrig demo --render) needs EGL or OSMesa; Debian packages.
render-deps:
	apt-get install -y --no-install-recommends libegl1 libgl1-mesa-dri libosmesa6

# libltc, only to cross-check handrig's own LTC decoder against another encoder
# (tests/handrig/devices/test_ltc_libltc.py, skipped without it); users need nothing.
ltc-deps:
	DEBIAN_FRONTEND=noninteractive apt-get install -y --no-install-recommends libltc11

# The live view's browser tests (tests/handrig/app/view) and `python -m bench view` drive
# Debian's headless chromium through chromium-driver. Needs root (CI runs as root).
browser-deps:
	DEBIAN_FRONTEND=noninteractive apt-get install -y --no-install-recommends chromium chromium-driver

# ---- glove firmware (firmware/glove/, firmware/README.md) --------------------------
# Debian packages: the AVR toolchain, the Arduino AVR core, and simavr for the
# in-the-loop tests (sim/avr_glove/). Needs root (CI runs as root).
FIRMWARE_DEBS := gcc-avr avr-libc arduino-core-avr simavr libsimavr-dev gcc make avrdude
ARDUINO_AVR ?= /usr/share/arduino/hardware/arduino/avr
FW_SRC := firmware/glove
FW_BUILD := build/firmware
FW_MCU ?= atmega328p
FW_F_CPU ?= 16000000L
# flash left for the sketch under the 2 KB bootloader of older Nanos (Uno/Optiboot: 0.5 KB)
FW_FLASH_BYTES ?= 30720
FW_RAM_BYTES ?= 2048
# e.g. make firmware FW_BUILD=build/fw500 FW_DEFS="-DGLOVE_RATE_HZ=500"
FW_DEFS ?=
AVR_CFLAGS := -mmcu=$(FW_MCU) -DF_CPU=$(FW_F_CPU) -DARDUINO=10819 -DARDUINO_AVR_NANO \
	-DARDUINO_ARCH_AVR $(FW_DEFS) -Os -g -ffunction-sections -fdata-sections \
	-I$(ARDUINO_AVR)/cores/arduino -I$(ARDUINO_AVR)/variants/eightanaloginputs \
	-I$(ARDUINO_AVR)/variants/standard -I$(ARDUINO_AVR)/libraries/Wire/src -I$(FW_SRC)
FW_WARN := -Wall -Wextra
AVR_CXXFLAGS := $(AVR_CFLAGS) -std=gnu++11 -fno-exceptions -fno-threadsafe-statics -fpermissive
FW_CORE_C := $(wildcard $(ARDUINO_AVR)/cores/arduino/*.c)
# WString.cpp needs a newer C++ than Debian's avr-g++ 5.4 (DECIMAL_DIG); the sketch uses no String
FW_CORE_CXX := $(filter-out %/WString.cpp,$(wildcard $(ARDUINO_AVR)/cores/arduino/*.cpp))
FW_CORE_OBJ := $(patsubst $(ARDUINO_AVR)/cores/arduino/%,$(FW_BUILD)/core/%.o,$(FW_CORE_C) $(FW_CORE_CXX)) \
	$(FW_BUILD)/core/Wire.cpp.o $(FW_BUILD)/core/twi.c.o
WIRE_SRC := $(ARDUINO_AVR)/libraries/Wire/src
FW_OBJ := $(FW_BUILD)/glove.ino.o $(FW_BUILD)/glove_core.c.o $(FW_BUILD)/board_avr.cpp.o \
	$(FW_BUILD)/board_arduino.cpp.o $(FW_BUILD)/board_i2c_wire.cpp.o
FW_HEADERS := $(wildcard $(FW_SRC)/*.h)
SIM_AVR_GLOVE := build/sim/avr_glove

.PHONY: firmware firmware-deps firmware-test sim-avr-glove flash

# Flash the glove through its USB serial port and the Arduino bootloader (STK500v1):
# make flash PORT=/dev/serial/by-id/usb-1a86_USB_Serial-if00-port0 (or /dev/ttyUSB0).
# FLASH_BAUD 57600 for a Nano with the old bootloader (most clones), 115200 for an Uno
# or a Nano with Optiboot. AVRDUDE_FLAGS=-n: avrdude's dry run (writes nothing).
FLASH_BAUD ?= 57600
FLASH_PROGRAMMER ?= arduino
AVRDUDE_FLAGS ?=
flash: $(FW_BUILD)/glove.hex
	$(if $(PORT),,$(error make flash needs the glove's port: make flash PORT=/dev/ttyUSB0 (or its /dev/serial/by-id/ name; firmware/README.md)))
	@command -v avrdude >/dev/null || { echo "avrdude not found: run 'make firmware-deps' (as root)"; exit 1; }
	avrdude -p $(FW_MCU) -c $(FLASH_PROGRAMMER) -P $(PORT) -b $(FLASH_BAUD) -D $(AVRDUDE_FLAGS) -U flash:w:$<:i

firmware-deps:
	DEBIAN_FRONTEND=noninteractive apt-get install -y --no-install-recommends $(FIRMWARE_DEBS)

firmware: $(FW_BUILD)/glove.hex
	@sh firmware/tools/size_report.sh $(FW_BUILD)/glove.elf $(FW_FLASH_BYTES) $(FW_RAM_BYTES)

$(FW_BUILD)/core/%.c.o: $(ARDUINO_AVR)/cores/arduino/%.c
	@command -v avr-gcc >/dev/null || { echo "avr-gcc not found: run 'make firmware-deps' (as root)"; exit 1; }
	@mkdir -p $(dir $@)
	avr-gcc $(AVR_CFLAGS) -std=gnu11 -c $< -o $@

$(FW_BUILD)/core/%.cpp.o: $(ARDUINO_AVR)/cores/arduino/%.cpp
	@mkdir -p $(dir $@)
	avr-g++ $(AVR_CXXFLAGS) -c $< -o $@

$(FW_BUILD)/core/Wire.cpp.o: $(WIRE_SRC)/Wire.cpp
	@mkdir -p $(dir $@)
	avr-g++ $(AVR_CXXFLAGS) -c $< -o $@

$(FW_BUILD)/core/twi.c.o: $(WIRE_SRC)/utility/twi.c
	@mkdir -p $(dir $@)
	avr-gcc $(AVR_CFLAGS) -std=gnu11 -w -c $< -o $@

$(FW_BUILD)/core.a: $(FW_CORE_OBJ)
	rm -f $@ && avr-gcc-ar rcs $@ $^

# The Arduino IDE's build of a sketch: the .ino is C++ with Arduino.h in front.
$(FW_BUILD)/glove.ino.cpp: $(FW_SRC)/glove.ino
	@command -v avr-gcc >/dev/null || { echo "avr-gcc not found: run 'make firmware-deps' (as root)"; exit 1; }
	@test -d $(ARDUINO_AVR)/cores/arduino || { echo "Arduino AVR core not found at $(ARDUINO_AVR): run 'make firmware-deps' (as root)"; exit 1; }
	@mkdir -p $(FW_BUILD)
	{ echo '#include <Arduino.h>'; echo '#line 1 "$<"'; cat $<; } > $@

$(FW_BUILD)/glove.ino.o: $(FW_BUILD)/glove.ino.cpp $(FW_HEADERS)
	avr-g++ $(AVR_CXXFLAGS) $(FW_WARN) -c $< -o $@

$(FW_BUILD)/%.c.o: $(FW_SRC)/%.c $(FW_HEADERS)
	@mkdir -p $(FW_BUILD)
	avr-gcc $(AVR_CFLAGS) $(FW_WARN) -std=gnu11 -c $< -o $@

$(FW_BUILD)/%.cpp.o: $(FW_SRC)/%.cpp $(FW_HEADERS)
	@mkdir -p $(FW_BUILD)
	avr-g++ $(AVR_CXXFLAGS) $(FW_WARN) -c $< -o $@

$(FW_BUILD)/glove.elf: $(FW_OBJ) $(FW_BUILD)/core.a
	avr-gcc -mmcu=$(FW_MCU) -Os -Wl,--gc-sections -o $@ $(FW_OBJ) $(FW_BUILD)/core.a -lm

$(FW_BUILD)/glove.hex: $(FW_BUILD)/glove.elf
	avr-objcopy -O ihex -R .eeprom $< $@

# The core compiled natively, checked against SPEC.md's golden bytes (also run by pytest).
firmware-test: $(STAMP)
	$(BIN)/python -m pytest -q tests/firmware

# The emulated chip: the firmware's ELF in simavr, ADC/I2C/UART wired to a recording.
sim-avr-glove: $(SIM_AVR_GLOVE)

$(SIM_AVR_GLOVE): sim/avr_glove/harness.c
	@test -f /usr/include/simavr/sim_avr.h || { echo "simavr headers not found: run 'make firmware-deps' (as root)"; exit 1; }
	@mkdir -p $(dir $@)
	cc -O2 -Wall -Wextra -std=gnu11 -I/usr/include/simavr $< -o $@ -lsimavr -lm
