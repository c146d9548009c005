"""Write the A2L that describes the Linux runner's XCP slave (fw_xcp.h).

    python firmware_sim/tools/make_a2l.py RUNNER OUT.a2l [--port 5555] [--host 127.0.0.1]
    python firmware_sim/tools/make_a2l.py RUNNER OUT.a2l --can 0x7F0,0x7F1

RUNNER is the built ``rhonn_runner`` (CMake, or ``build_runner.py``). The
A2L has, for a calibration and measurement tool (CANape, INCA, pyxcp):

- MEASUREMENTs: every weight ``w<i>_<t>`` of the identifier, the prediction
  ``xhat_<state>``, the health ``innovation_<state>``, ``nis_<i>``,
  ``trace_p_<i>`` and counters, the application's counters and the XCP ones;
- the CHARACTERISTICs of the calibration page: ``learning``, and every
  neuron's trace ceiling ``trace_ceiling_<i>`` and innovation gate
  ``gate_<i>`` (0 off; the slave refuses what the core refuses);
- COMPU_METHODs with units (the states' units from the DBC's scalings), a
  verbal table for the learning switch;
- the event list (one event, ``step``: once per identifier step) and
  ``IF_DATA XCP`` for XCP on UDP (the host and port the runner was given),
  or with ``--can CMD_ID,RES_ID`` for XCP on CAN FD (``XCP_ON_CAN`` with its
  ``CAN_FD`` block: the identifiers of the runner's ``--xcp-can``).

ADDRESSES. An XCP address is an offset from the image's load address, which
the runner takes as ``__executable_start`` (the image is a PIE, loaded at a
different base each run). So each ECU_ADDRESS is the symbol's value as ``nm``
shows it minus that of ``__executable_start`` (0 for a PIE): the same in
every run, whatever the load address. The symbols are
``rhonn_xcp_signals`` and ``rhonn_xcp_calibration``; the offsets inside
them are the ``FW_XCP_OFF_*`` macros of fw_xcp.h, which the C code checks
against the structures at compile time. The identifier's terms per neuron
come from its header (config/lim_identifier_f32.h).
"""
from __future__ import annotations

import argparse
import re
import shutil
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

HERE = Path(__file__).resolve().parent
FIRMWARE = HERE.parent
XCP_HEADER = FIRMWARE / "app" / "fw_xcp.h"
IDENTIFIER_HEADER = FIRMWARE / "config" / "lim_identifier_f32.h"
SIGNALS_SYMBOL = "rhonn_xcp_signals"
CALIBRATION_SYMBOL = "rhonn_xcp_calibration"
BASE_SYMBOL = "__executable_start"

# The LIM's states (the DBC's Measurement signals) and their units.
STATES: tuple[tuple[str, str], ...] = (("qm", "m"), ("v", "m/s"), ("lambda_a", "Wb"), ("lambda_b", "Wb"),
                                       ("ia", "A"), ("ib", "A"))

# The A2ML of the IF_DATA XCP subset written below (ASAM MCD-1 XCP's blocks
# PROTOCOL_LAYER, DAQ with TIMESTAMP_SUPPORTED and EVENT, XCP_ON_UDP_IP, XCP_ON_CAN with CAN_FD).
A2ML = """    /begin A2ML
      block "IF_DATA" taggedunion if_data {
        "XCP" struct {
          taggedstruct {
            block "PROTOCOL_LAYER" struct {
              uint; uint; uint; uint; uint; uint; uint; uint;
              uchar; uint;
              enum { "BYTE_ORDER_MSB_LAST" = 0, "BYTE_ORDER_MSB_FIRST" = 1 };
              enum { "ADDRESS_GRANULARITY_BYTE" = 1, "ADDRESS_GRANULARITY_WORD" = 2,
                     "ADDRESS_GRANULARITY_DWORD" = 4 };
              taggedstruct {
                ("OPTIONAL_CMD" enum {
                  "GET_COMM_MODE_INFO" = 251, "GET_ID" = 250, "GET_SEED" = 248, "UNLOCK" = 247,
                  "SET_MTA" = 246, "UPLOAD" = 245, "SHORT_UPLOAD" = 244, "DOWNLOAD" = 240,
                  "SET_DAQ_PTR" = 226, "WRITE_DAQ" = 225, "SET_DAQ_LIST_MODE" = 224,
                  "START_STOP_DAQ_LIST" = 222, "START_STOP_SYNCH" = 221, "GET_DAQ_CLOCK" = 220,
                  "GET_DAQ_PROCESSOR_INFO" = 218, "GET_DAQ_RESOLUTION_INFO" = 217,
                  "FREE_DAQ" = 214, "ALLOC_DAQ" = 213, "ALLOC_ODT" = 212, "ALLOC_ODT_ENTRY" = 211
                })*;
              };
            };
            block "DAQ" struct {
              enum { "STATIC" = 0, "DYNAMIC" = 1 };
              uint; uint; uchar;
              enum { "OPTIMISATION_TYPE_DEFAULT" = 0 };
              enum { "ADDRESS_EXTENSION_FREE" = 0, "ADDRESS_EXTENSION_ODT" = 1, "ADDRESS_EXTENSION_DAQ" = 3 };
              enum { "IDENTIFICATION_FIELD_TYPE_ABSOLUTE" = 0, "IDENTIFICATION_FIELD_TYPE_RELATIVE_BYTE" = 1 };
              enum { "GRANULARITY_ODT_ENTRY_SIZE_DAQ_BYTE" = 1 };
              uchar;
              enum { "NO_OVERLOAD_INDICATION" = 0, "OVERLOAD_INDICATION_PID" = 1, "OVERLOAD_INDICATION_EVENT" = 2 };
              taggedstruct {
                "PRESCALER_SUPPORTED";
                block "TIMESTAMP_SUPPORTED" struct {
                  uint;
                  enum { "NO_TIME_STAMP" = 0, "SIZE_BYTE" = 1, "SIZE_WORD" = 2, "SIZE_DWORD" = 4 };
                  enum { "UNIT_1NS" = 0, "UNIT_10NS" = 1, "UNIT_100NS" = 2, "UNIT_1US" = 3, "UNIT_10US" = 4,
                         "UNIT_100US" = 5, "UNIT_1MS" = 6, "UNIT_10MS" = 7, "UNIT_100MS" = 8, "UNIT_1S" = 9 };
                  taggedstruct { "TIMESTAMP_FIXED"; };
                };
                (block "EVENT" struct {
                  char[101]; char[9]; uint;
                  enum { "DAQ" = 1, "STIM" = 2, "DAQ_STIM" = 3 };
                  uchar; uchar; uchar; uchar;
                })*;
              };
            };
            block "XCP_ON_UDP_IP" struct {
              uint; uint;
              taggedunion { "HOST_NAME" char[256]; "ADDRESS" char[15]; };
            };
            block "XCP_ON_CAN" struct {
              uint;
              taggedstruct {
                "CAN_ID_MASTER" ulong;
                "CAN_ID_SLAVE" ulong;
                "BAUDRATE" ulong;
                "SAMPLE_POINT" uchar;
                "SAMPLE_RATE" enum { "SINGLE" = 1, "TRIPLE" = 3 };
                "BTL_CYCLES" uchar;
                "SJW" uchar;
                "SYNC_EDGE" enum { "SINGLE" = 1, "DUAL" = 2 };
                "MAX_DLC_REQUIRED";
                block "CAN_FD" struct {
                  taggedstruct {
                    "MAX_DLC" uint;
                    "CAN_FD_DATA_TRANSFER_BAUDRATE" ulong;
                    "SAMPLE_POINT" uchar;
                    "BTL_CYCLES" uchar;
                    "SJW" uchar;
                    "SYNC_EDGE" enum { "SINGLE" = 1, "DUAL" = 2 };
                    "MAX_DLC_REQUIRED";
                    "SECONDARY_SAMPLE_POINT" uchar;
                    "TRANSCEIVER_DELAY_COMPENSATION" enum { "OFF" = 0, "ON" = 1 };
                  };
                };
              };
            };
          };
        };
      };
    /end A2ML
"""


@dataclass(frozen=True)
class Layout:
    """What the C headers say: the A2L name, the packet sizes, the offsets
    inside the two regions and the identifier's terms per neuron."""

    name: str
    max_cto: int
    max_dto: int
    max_entry: int
    terms_capacity: int
    signal_offsets: dict[str, int]
    calibration_offsets: dict[str, int]
    n_terms: tuple[int, ...]

    def __post_init__(self) -> None:
        if not re.fullmatch(r"[A-Za-z_][A-Za-z0-9_]*", self.name):
            raise ValueError(f"name: {self.name!r} is not an A2L identifier")
        if len(self.n_terms) != len(STATES) or not all(1 <= n <= self.terms_capacity for n in self.n_terms):
            raise ValueError(f"n_terms: {self.n_terms} must be {len(STATES)} values in 1..{self.terms_capacity}")


@dataclass(frozen=True)
class CanTransport:
    """XCP on CAN FD (the runner's ``--xcp-can IFACE,CMD_ID,RES_ID``): the
    master's command identifier, the slave's response (and DAQ) identifier,
    11-bit, and the bus's bit rates for the tool's interface (the runner
    takes whatever its interface is configured with)."""

    cmd_id: int
    res_id: int
    bitrate: int = 500_000
    data_bitrate: int = 2_000_000

    def __post_init__(self) -> None:
        for name in ("cmd_id", "res_id"):
            value = getattr(self, name)
            if not isinstance(value, int) or not 0 <= value <= 0x7FF:
                raise ValueError(f"{name}: {value!r} is not an 11-bit CAN identifier (0..0x7FF)")
        if self.cmd_id == self.res_id:
            raise ValueError(f"cmd_id, res_id: both are {self.cmd_id:#x}; they must differ")
        from pyrhonn.firmware import database

        taken = {m.frame_id: m.name for m in database().messages}
        for name in ("cmd_id", "res_id"):
            value = getattr(self, name)
            if value in taken:
                raise ValueError(f"{name}: {value:#x} is the application's {taken[value]} frame")
        for name in ("bitrate", "data_bitrate"):
            value = getattr(self, name)
            if not isinstance(value, int) or not 0 < value <= 0xFFFFFFFF:
                raise ValueError(f"{name}: {value!r} is not a bit rate in bit/s (1..4294967295)")

    def if_data(self) -> str:
        """The IF_DATA XCP block XCP_ON_CAN with its CAN_FD part: packets up to 64 bytes, padded to
        the next CAN FD length (MAX_DLC_REQUIRED is not set)."""
        return (f"      /begin XCP_ON_CAN 0x0104\n"
                f"        CAN_ID_MASTER 0x{self.cmd_id:X}\n"
                f"        CAN_ID_SLAVE 0x{self.res_id:X}\n"
                f"        BAUDRATE {self.bitrate}\n"
                f"        /begin CAN_FD\n"
                f"          MAX_DLC 64\n"
                f"          CAN_FD_DATA_TRANSFER_BAUDRATE {self.data_bitrate}\n"
                f"        /end CAN_FD\n"
                f"      /end XCP_ON_CAN\n")


def parse_can_ids(text: str) -> tuple[int, int]:
    """``CMD_ID,RES_ID``, each 0x-hex or decimal, as two ints. ValueError
    naming the part that is not a number (the range is CanTransport's)."""
    parts = text.split(",")
    if len(parts) != 2:
        raise ValueError(f"--can: takes CMD_ID,RES_ID (e.g. 0x7F0,0x7F1), got {text!r}")
    ids = []
    for name, part in zip(("CMD_ID", "RES_ID"), parts):
        if not re.fullmatch(r"0[xX][0-9a-fA-F]{1,8}|[0-9]{1,10}", part):
            raise ValueError(f"--can: {name} {part!r} is not a number (0x-hex or decimal)")
        ids.append(int(part, 0) if part[:2].lower() == "0x" else int(part, 10))
    return ids[0], ids[1]


def _defines(text: str) -> dict[str, str]:
    return {m.group(1): m.group(2) for m in re.finditer(r"^#define\s+(\w+)\s+(\S.*?)\s*(?:/\*.*)?$", text, re.M)}


def _uint(defines: dict[str, str], key: str) -> int:
    value = defines.get(key)
    if value is None or not re.fullmatch(r"\d+u?", value):
        raise ValueError(f"{key}: not an unsigned constant in fw_xcp.h ({value!r})")
    return int(value.rstrip("u"))


def read_layout(xcp_header: Path = XCP_HEADER, identifier_header: Path = IDENTIFIER_HEADER) -> Layout:
    """The layout from fw_xcp.h and the identifier's header. ValueError
    naming the missing or malformed item."""
    d = _defines(xcp_header.read_text())
    name = d.get("FW_XCP_A2L_NAME", "")
    if not re.fullmatch(r'"[^"]*"', name):
        raise ValueError(f"FW_XCP_A2L_NAME: not a string in {xcp_header.name}")
    sig = {k[len("FW_XCP_OFF_"):].lower(): _uint(d, k) for k in d if k.startswith("FW_XCP_OFF_")}
    sig["size"] = _uint(d, "FW_XCP_SIGNALS_SIZE")
    cal = {k[len("FW_XCP_CAL_OFF_"):].lower(): _uint(d, k) for k in d if k.startswith("FW_XCP_CAL_OFF_")}
    cal["size"] = _uint(d, "FW_XCP_CALIBRATION_SIZE")
    text = identifier_header.read_text()
    start = text.find("LIM_IDENTIFIER = {")
    if start < 0:
        raise ValueError(f"{identifier_header.name}: no LIM_IDENTIFIER")
    terms = tuple(int(m.group(1)) for m in re.finditer(r"(\d+), /\* n_terms \*/", text[start:]))[:len(STATES)]
    return Layout(name=name.strip('"'), max_cto=_uint(d, "FW_XCP_MAX_CTO"), max_dto=_uint(d, "FW_XCP_MAX_DTO"),
                  max_entry=_uint(d, "FW_XCP_MAX_ENTRY_SIZE"), terms_capacity=_uint(d, "FW_XCP_TERMS"),
                  signal_offsets=sig, calibration_offsets=cal, n_terms=terms)


def symbol_addresses(runner: Path, names: tuple[str, ...] = (SIGNALS_SYMBOL, CALIBRATION_SYMBOL)) -> dict[str, int]:
    """Each symbol's XCP address: its value minus __executable_start's, from
    ``nm``. FileNotFoundError for a missing runner or nm, ValueError naming
    a symbol the image does not define."""
    if not runner.is_file():
        raise FileNotFoundError(f"runner: no such file {runner}")
    nm = shutil.which("nm")
    if nm is None:
        raise FileNotFoundError("nm (binutils) is not on PATH")
    out = subprocess.run([nm, "--defined-only", str(runner)], check=True, capture_output=True, text=True).stdout
    table: dict[str, int] = {}
    for line in out.splitlines():
        parts = line.split()
        if len(parts) == 3:
            table[parts[2]] = int(parts[0], 16)
    missing = [n for n in (BASE_SYMBOL, *names) if n not in table]
    if missing:
        raise ValueError(f"runner: {runner.name} defines no {', '.join(missing)} (built without fw_xcp?)")
    base = table[BASE_SYMBOL]
    result = {n: table[n] - base for n in names}
    for n, a in result.items():
        if not 0 <= a <= 0xFFFFFFFF:
            raise ValueError(f"{n}: address {a:#x} is not within 4 GiB above {BASE_SYMBOL}")
    return result


def _measurement(name: str, text: str, dtype: str, compu: str, lo: float, hi: float, address: int) -> str:
    return (f"    /begin MEASUREMENT {name} \"{text}\" {dtype} {compu} 0 0 {lo} {hi}\n"
            f"      ECU_ADDRESS 0x{address:X}\n    /end MEASUREMENT\n")


def a2l_text(layout: Layout, addresses: dict[str, int], host: str, port: int,
             can: CanTransport | None = None) -> str:
    """The A2L (ASAP2 1.71) of the slave: its transport XCP on UDP (host,
    port), or XCP on CAN FD when ``can`` is given."""
    if can is not None and max(layout.max_cto, layout.max_dto) > 64:
        raise ValueError(f"can: MAX_CTO {layout.max_cto} / MAX_DTO {layout.max_dto} do not fit a CAN FD frame (64)")
    if not 0 <= port <= 65535:
        raise ValueError(f"port: {port} is not in 0..65535")
    if not re.fullmatch(r"\d{1,3}(\.\d{1,3}){3}", host):
        raise ValueError(f"host: {host!r} is not an IPv4 address")
    sig = addresses[SIGNALS_SYMBOL]
    cal = addresses[CALIBRATION_SYMBOL]
    off = layout.signal_offsets
    f32 = 3.4e38
    u32 = 4294967295
    items: list[str] = []
    groups: dict[str, list[str]] = {"weights": [], "prediction": [], "health": [], "counters": []}
    for i, n in enumerate(layout.n_terms):
        for t in range(n):
            name = f"w{i}_{t}"
            items.append(_measurement(name, f"weight {t} of neuron {i} ({STATES[i][0]})", "FLOAT32_IEEE", "CM_ONE",
                                      -f32, f32, sig + off["weights"] + 4 * (i * layout.terms_capacity + t)))
            groups["weights"].append(name)
    for i, (state, _unit) in enumerate(STATES):
        for key, text, group in (("xhat", f"prediction of {state} for the next sample", "prediction"),
                                 ("innovation", f"innovation e of {state}'s last update", "health")):
            name = f"{key}_{state}"
            items.append(_measurement(name, text, "FLOAT32_IEEE", f"CM_{state.upper()}", -f32, f32,
                                      sig + off[key] + 4 * i))
            groups[group].append(name)
        for key, text, dtype, compu, lo, hi in (
                ("nis", "normalised innovation squared e^2/s", "FLOAT32_IEEE", "CM_ONE", -f32, f32),
                ("trace_p", "trace of the covariance P", "FLOAT32_IEEE", "CM_ONE", -f32, f32),
                ("updates", "learning updates committed", "ULONG", "CM_COUNT", 0, u32),
                ("refused", "learning updates refused", "ULONG", "CM_COUNT", 0, u32),
                ("bounded", "updates bounded by the trace ceiling", "ULONG", "CM_COUNT", 0, u32),
                ("gated", "updates skipped by the innovation gate", "ULONG", "CM_COUNT", 0, u32),
                ("resets", "automatic covariance resets", "ULONG", "CM_COUNT", 0, u32)):
            name = f"{key}_{i}"
            items.append(_measurement(name, f"neuron {i}: {text}", dtype, compu, lo, hi, sig + off[key] + 4 * i))
            groups["health"].append(name)
    for key, text in (("measurements", "accepted measurements (steps run)"), ("step_errors", "steps refused"),
                      ("lost_frames", "Measurements the sequence counter skipped"),
                      ("rejected", "frames rejected"), ("restarts", "identifier restarts after a gap"),
                      ("events", "step events seen by XCP"), ("daq_dto_sent", "DAQ packets sent"),
                      ("daq_dto_lost", "DAQ packets the transport refused")):
        items.append(_measurement(key, text, "ULONG", "CM_COUNT", 0, u32, sig + off[key]))
        groups["counters"].append(key)
    items.append(_measurement("learning_state", "learning on (1) or frozen (0)", "ULONG", "CM_LEARNING", 0, 1,
                              sig + off["learning"]))
    items.append(_measurement("step_status", "rhonn_status of the last step", "ULONG", "CM_COUNT", 0, 15,
                              sig + off["step_status"]))
    groups["counters"] += ["learning_state", "step_status"]
    compu = ['    /begin COMPU_METHOD CM_ONE "dimensionless" IDENTICAL "%12.6" "" /end COMPU_METHOD\n',
             '    /begin COMPU_METHOD CM_COUNT "count" IDENTICAL "%10.0" "" /end COMPU_METHOD\n',
             '    /begin COMPU_METHOD CM_LEARNING "learning switch" TAB_VERB "%1.0" ""\n'
             '      COMPU_TAB_REF VT_LEARNING\n    /end COMPU_METHOD\n',
             '    /begin COMPU_VTAB VT_LEARNING "learning switch" TAB_VERB 2 0 "frozen" 1 "learning"'
             ' /end COMPU_VTAB\n']
    for state, unit in STATES:
        compu.append(f'    /begin COMPU_METHOD CM_{state.upper()} "{state}" IDENTICAL "%12.6" "{unit}"'
                     ' /end COMPU_METHOD\n')
    optional = ("GET_COMM_MODE_INFO GET_ID GET_SEED UNLOCK SET_MTA UPLOAD SHORT_UPLOAD DOWNLOAD SET_DAQ_PTR "
                "WRITE_DAQ SET_DAQ_LIST_MODE START_STOP_DAQ_LIST START_STOP_SYNCH GET_DAQ_CLOCK "
                "GET_DAQ_PROCESSOR_INFO GET_DAQ_RESOLUTION_INFO FREE_DAQ ALLOC_DAQ ALLOC_ODT ALLOC_ODT_ENTRY").split()
    if_data = (
        "    /begin IF_DATA XCP\n"
        "      /begin PROTOCOL_LAYER 0x0104 1000 1000 1000 1000 1000 1000 1000"
        f" {layout.max_cto} {layout.max_dto} BYTE_ORDER_MSB_LAST ADDRESS_GRANULARITY_BYTE\n"
        + "".join(f"        OPTIONAL_CMD {c}\n" for c in optional)
        + "      /end PROTOCOL_LAYER\n"
        "      /begin DAQ DYNAMIC 0 1 0 OPTIMISATION_TYPE_DEFAULT ADDRESS_EXTENSION_FREE"
        f" IDENTIFICATION_FIELD_TYPE_ABSOLUTE GRANULARITY_ODT_ENTRY_SIZE_DAQ_BYTE {layout.max_entry}"
        " NO_OVERLOAD_INDICATION\n"
        "        PRESCALER_SUPPORTED\n"
        "        /begin TIMESTAMP_SUPPORTED 1 SIZE_DWORD UNIT_1US TIMESTAMP_FIXED /end TIMESTAMP_SUPPORTED\n"
        '        /begin EVENT "step" "step" 0 DAQ 255 0 0 0 /end EVENT\n'
        "      /end DAQ\n"
        + (can.if_data() if can is not None else
           f'      /begin XCP_ON_UDP_IP 0x0104 {port} ADDRESS "{host}" /end XCP_ON_UDP_IP\n')
        + "    /end IF_DATA\n")
    tuned = [(f"{key}_{i}", f"neuron {i}: {text}, taken before the next step",
              cal + layout.calibration_offsets[key] + 4 * i)
             for key, text in (("trace_ceiling", "trace ceiling of P (0 off, else at least trace P(0))"),
                               ("gate", "innovation gate on e^2/s (0 off)"))
             for i in range(len(STATES))]
    characteristic = (
        f'    /begin CHARACTERISTIC learning "learning switch: 0 freezes the weights from the next step,'
        f' 1 resumes" VALUE 0x{cal + layout.calibration_offsets["learning"]:X} RL_UBYTE 0 CM_LEARNING 0 1\n'
        "    /end CHARACTERISTIC\n"
        + "".join(f'    /begin CHARACTERISTIC {name} "{text}" VALUE 0x{addr:X} RL_FLOAT32 0 CM_ONE 0 {f32}\n'
                  "    /end CHARACTERISTIC\n" for name, text, addr in tuned)
        + "    /begin RECORD_LAYOUT RL_UBYTE FNC_VALUES 1 UBYTE ROW_DIR DIRECT /end RECORD_LAYOUT\n"
        "    /begin RECORD_LAYOUT RL_FLOAT32 FNC_VALUES 1 FLOAT32_IEEE ROW_DIR DIRECT /end RECORD_LAYOUT\n")
    group_text = "".join(
        f'    /begin GROUP {g} "{g}" /begin REF_MEASUREMENT {" ".join(names)} /end REF_MEASUREMENT /end GROUP\n'
        for g, names in groups.items())
    group_text += ('    /begin GROUP calibration "calibratables" /begin REF_CHARACTERISTIC learning '
                   + " ".join(name for name, _, _ in tuned) + ' /end REF_CHARACTERISTIC /end GROUP\n')
    return ("ASAP2_VERSION 1 71\n"
            f'/begin PROJECT {layout.name} "RHONN identifier of the LIM, firmware over XCP"\n'
            f'  /begin HEADER "" VERSION "1" PROJECT_NO {layout.name} /end HEADER\n'
            f'  /begin MODULE {layout.name} "the Linux runner\'s XCP slave (fw_xcp)"\n'
            + A2ML
            + '    /begin MOD_COMMON "" BYTE_ORDER MSB_LAST ALIGNMENT_BYTE 1 ALIGNMENT_WORD 1'
            " ALIGNMENT_LONG 1 ALIGNMENT_FLOAT32_IEEE 1 ALIGNMENT_FLOAT64_IEEE 1 /end MOD_COMMON\n"
            + if_data + "".join(compu) + characteristic + "".join(items) + group_text
            + "  /end MODULE\n/end PROJECT\n")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("runner", type=Path, help="the built rhonn_runner")
    parser.add_argument("output", type=Path, help="the A2L file to write")
    parser.add_argument("--host", help="the runner's --xcp-udp address (default 127.0.0.1)")
    parser.add_argument("--port", type=int, help="the runner's --xcp-udp port (default 5555)")
    parser.add_argument("--can", metavar="CMD_ID,RES_ID",
                        help="XCP on CAN FD instead of UDP: the runner's --xcp-can identifiers (its defaults: "
                             "0x7F0,0x7F1)")
    parser.add_argument("--can-bitrate", type=int, default=500_000, help="arbitration bit rate (default 500000)")
    parser.add_argument("--can-data-bitrate", type=int, default=2_000_000,
                        help="CAN FD data bit rate (default 2000000)")
    args = parser.parse_args(argv)
    try:
        can = None
        if args.can is not None:
            if args.host is not None or args.port is not None:
                raise ValueError("--can: XCP on CAN has no --host or --port (those are XCP on UDP's)")
            can = CanTransport(*parse_can_ids(args.can), bitrate=args.can_bitrate, data_bitrate=args.can_data_bitrate)
        host = "127.0.0.1" if args.host is None else args.host
        port = 5555 if args.port is None else args.port
        text = a2l_text(read_layout(), symbol_addresses(args.runner), host, port, can)
    except (OSError, ValueError, subprocess.CalledProcessError) as exc:
        print(f"make_a2l: {exc}", file=sys.stderr)
        return 1
    from pyrhonn.atomic import write_text
    write_text(args.output, text)
    print(args.output)
    return 0


if __name__ == "__main__":
    sys.exit(main())
