/*
 * fw_xcp.h - an XCP 1.4 slave for the identifier application: a
 * calibration and measurement tool (CANape, INCA, pyxcp) watches the
 * running identifier and tunes it, described by an A2L
 * (firmware_sim/tools/make_a2l.py).
 *
 * The protocol layer only: one command packet (CTO) in, its response out
 * through the transport's send, and the DAQ packets (DTO) of the step
 * event. The transport (XCP on UDP in the Linux runner: the LEN/CTR header)
 * wraps each packet. Caller-owned, no allocation, no stdio; the work per
 * call is bounded by the compile-time capacities below.
 *
 * COMMANDS. CONNECT, DISCONNECT, GET_STATUS, SYNCH, GET_COMM_MODE_INFO,
 * GET_ID (type 0 and 1: the A2L name, FW_XCP_A2L_NAME, uploaded from the MTA),
 * SET_MTA, UPLOAD, SHORT_UPLOAD, DOWNLOAD, GET_SEED, UNLOCK, and dynamic
 * DAQ: GET_DAQ_PROCESSOR_INFO, GET_DAQ_RESOLUTION_INFO, GET_DAQ_CLOCK,
 * FREE_DAQ, ALLOC_DAQ, ALLOC_ODT, ALLOC_ODT_ENTRY, SET_DAQ_PTR, WRITE_DAQ,
 * SET_DAQ_LIST_MODE, START_STOP_DAQ_LIST, START_STOP_SYNCH. Anything else is
 * answered ERR_CMD_UNKNOWN; a malformed packet ERR_CMD_SYNTAX; before
 * CONNECT only CONNECT is answered (the standard's "not connected": silence).
 *
 * MEMORY. An XCP address (32 bits, extension 0) is an offset from the
 * platform's address_base (fw_xcp_config): the byte at address A is the one
 * at address_base + A. Only two regions exist: the signals (fw_xcp_signals,
 * read only) and the calibration page (fw_xcp_calibration, read and
 * write). Every access must lie wholly inside one of them, else
 * ERR_ACCESS_DENIED (or ERR_WRITE_PROTECTED for a write to the signals):
 * no other byte of the image can be read or written. Extension 0xFF is the
 * GET_ID text, read only.
 *
 * PROTECTION. CAL/PAG (DOWNLOAD) and DAQ (the DAQ commands) are locked at
 * CONNECT. GET_SEED returns a 16-byte seed; UNLOCK must answer it with
 * key = AES-CMAC(K, seed) (16 bytes), K the firmware's command key
 * (config/fw_secoc_key.h). A wrong key is answered ERR_ACCESS_LOCKED and
 * disconnects, as the standard prescribes; UNLOCK without a seed is
 * ERR_SEQUENCE. Reading (UPLOAD, SHORT_UPLOAD) is not protected.
 *
 * CALIBRATION. DOWNLOAD writes the calibration page after checking every
 * value (learning 0 or 1; a trace ceiling or a gate the core accepts:
 * finite, >= 0, a ceiling 0 or >= trace P_i(0); else ERR_OUT_OF_RANGE,
 * nothing written). The identifier takes the page before its next step (the
 * application's before-step hook), never inside one.
 *
 * DAQ. One event channel, FW_XCP_EVENT_STEP: once per identifier step
 * (every accepted Measurement), after the Estimate went out. While a DAQ
 * list runs, the signals its entries read are refreshed from the identifier
 * (the neurons' weights, health and the prediction only where an entry
 * reads them; the counters always), then every
 * running list on the event (prescaler counted) sends its ODTs (without
 * DAQ, UPLOAD and SHORT_UPLOAD refresh them before they read, so a step
 * costs the slave nothing but a counter): PID = absolute ODT number, a
 * 4-byte timestamp (1 us, the Measurement's reception time) after the
 * first ODT's PID, then the entries' bytes. Starting a list (START_STOP_DAQ_LIST,
 * START_STOP_SYNCH) compiles the running lists' ODTs into runs of
 * contiguous bytes, so an event copies each run at once. A DTO the transport refuses is
 * counted in fw_xcp_signals.daq_dto_lost (also readable over XCP).
 */
#ifndef FW_XCP_H
#define FW_XCP_H

#include <stddef.h>
#include <stdint.h>

#include "fw_aes_cmac.h"
#include "fw_app.h"

#ifdef __cplusplus
extern "C" {
#endif

/* The A2L's name (PROJECT and MODULE): GET_ID types 0 and 1 return it. */
#define FW_XCP_A2L_NAME "RHONN_LIM"

#define FW_XCP_MAX_CTO 64u        /* command / response packet: fits a CAN FD frame */
#define FW_XCP_MAX_DTO 64u        /* DAQ packet */
#define FW_XCP_MAX_DAQ 4u         /* DAQ lists */
#define FW_XCP_MAX_ODT 24u        /* ODTs over all lists */
#define FW_XCP_MAX_ENTRIES 192u   /* ODT entries over all lists */
#define FW_XCP_MAX_ENTRY_SIZE 59u /* bytes in one ODT entry (MAX_DTO less PID and timestamp) */
#define FW_XCP_SEED_LEN 16u
#define FW_XCP_KEY_LEN 16u
#define FW_XCP_EVENT_STEP 0u      /* the only event channel */
#define FW_XCP_EXT_ID 0xFFu       /* address extension of the GET_ID text */

/* Terms per neuron in the signals (weights): an identifier with more is
 * refused by fw_xcp_attach. */
#define FW_XCP_TERMS 12u

/* The signals, refreshed at every step event while DAQ runs, else by each
 * read: all 4-byte values, in this
 * fixed layout (the FW_XCP_OFF_* offsets, checked at compile time, are what
 * make_a2l.py reads). Little-endian on every supported target. */
typedef struct {
    float weights[FW_N_STATES][FW_XCP_TERMS]; /* w_i, terms past L_i are 0 */
    float xhat[FW_N_STATES];                  /* the prediction x_hat(k+1) of the last step */
    float innovation[FW_N_STATES];            /* rhonn_health: e_i of the last update */
    float nis[FW_N_STATES];                   /* e_i^2 / s_i */
    float trace_p[FW_N_STATES];               /* trace P_i */
    uint32_t updates[FW_N_STATES];
    uint32_t refused[FW_N_STATES];            /* rhonn_health.rejected */
    uint32_t bounded[FW_N_STATES];
    uint32_t gated[FW_N_STATES];
    uint32_t resets[FW_N_STATES];
    uint32_t measurements;                    /* fw_counters */
    uint32_t step_errors;
    uint32_t lost_frames;
    uint32_t rejected;
    uint32_t restarts;
    uint32_t learning;                        /* 1 learning, 0 frozen */
    uint32_t step_status;                     /* rhonn_status of the last step */
    uint32_t events;                          /* step events seen by XCP */
    uint32_t daq_dto_sent;                    /* DAQ packets the transport took */
    uint32_t daq_dto_lost;                    /* DAQ packets the transport refused */
} fw_xcp_signals;

#define FW_XCP_OFF_WEIGHTS 0u
#define FW_XCP_OFF_XHAT 288u
#define FW_XCP_OFF_INNOVATION 312u
#define FW_XCP_OFF_NIS 336u
#define FW_XCP_OFF_TRACE_P 360u
#define FW_XCP_OFF_UPDATES 384u
#define FW_XCP_OFF_REFUSED 408u
#define FW_XCP_OFF_BOUNDED 432u
#define FW_XCP_OFF_GATED 456u
#define FW_XCP_OFF_RESETS 480u
#define FW_XCP_OFF_MEASUREMENTS 504u
#define FW_XCP_OFF_STEP_ERRORS 508u
#define FW_XCP_OFF_LOST_FRAMES 512u
#define FW_XCP_OFF_REJECTED 516u
#define FW_XCP_OFF_RESTARTS 520u
#define FW_XCP_OFF_LEARNING 524u
#define FW_XCP_OFF_STEP_STATUS 528u
#define FW_XCP_OFF_EVENTS 532u
#define FW_XCP_OFF_DAQ_DTO_SENT 536u
#define FW_XCP_OFF_DAQ_DTO_LOST 540u
#define FW_XCP_SIGNALS_SIZE 544u

/* The calibration page (RAM): the learning switch, and every neuron's trace
 * ceiling and innovation gate (rhonn_set_trace_ceiling, rhonn_set_gate: 0
 * off). Until written, the page shows the values in force. */
typedef struct {
    uint8_t learning;       /* 1 learn, 0 freeze; taken before the next step */
    uint8_t reserved[3];    /* written as 0 */
    float trace_ceiling[FW_N_STATES]; /* 0 off, else >= trace P_i(0); taken before the next step */
    float gate[FW_N_STATES];          /* 0 off, else the largest e^2 / s learned; likewise */
} fw_xcp_calibration;

#define FW_XCP_CAL_OFF_LEARNING 0u
#define FW_XCP_CAL_OFF_TRACE_CEILING 4u
#define FW_XCP_CAL_OFF_GATE 28u
#define FW_XCP_CALIBRATION_SIZE 52u

/* The transport: send one XCP packet (a response, an error or a DTO),
 * without the transport's header. FW_OK, or FW_E_HAL when it was not sent. */
typedef struct {
    void *ctx;
    fw_status (*send)(void *ctx, const uint8_t *packet, size_t len);
} fw_xcp_transport;

typedef struct {
    fw_xcp_transport transport;
    fw_xcp_signals *signals;        /* the platform's objects, named in the A2L */
    fw_xcp_calibration *calibration;
    uintptr_t address_base;         /* XCP address 0; each region must lie within 4 GiB above it */
} fw_xcp_config;

typedef struct {
    uint8_t region;     /* 0 signals, 1 calibration */
    uint8_t size;
    uint16_t offset;
} fw_xcp_entry;

typedef struct {
    uint8_t first_odt;  /* index into odt[] (the absolute ODT number: the PID) */
    uint8_t n_odt;
    uint8_t mode;       /* SET_DAQ_LIST_MODE's mode byte (timestamp bit) */
    uint8_t prescaler;
    uint8_t countdown;
    uint8_t selected;
    uint8_t running;
    uint8_t configured; /* SET_DAQ_LIST_MODE seen */
} fw_xcp_daq;

typedef struct {
    uint16_t first_entry;
    uint8_t n_entries;
    uint8_t bytes;      /* written so far */
    uint16_t first_run; /* its runs in run_off/run_len (compiled when a list starts) */
    uint8_t n_runs;
} fw_xcp_odt;

typedef struct {
    uint32_t magic;
    fw_xcp_transport transport;
    fw_xcp_signals *signals;
    fw_xcp_calibration *calibration;
    uintptr_t address_base;
    uint32_t sig_address, cal_address;  /* the regions' XCP addresses */
    fw_cmac_key key;
    uint8_t connected;
    uint8_t protection;                 /* resource bits still locked */
    uint8_t seed_resource;              /* resource of the outstanding seed (0: none) */
    uint8_t cal_dirty;                  /* the page changed since the identifier took it */
    uint8_t seed[FW_XCP_SEED_LEN];
    uint32_t seed_counter;
    uint8_t mta_ext;
    uint32_t mta;
    /* dynamic DAQ */
    uint8_t alloc_stage;                /* 0 free, 1 DAQ, 2 ODT, 3 entries allocated */
    uint8_t n_daq;
    uint8_t n_odt;
    uint16_t n_entries;
    uint8_t ptr_valid;
    uint8_t ptr_daq, ptr_odt, ptr_entry;
    fw_xcp_daq daq[FW_XCP_MAX_DAQ];
    fw_xcp_odt odt[FW_XCP_MAX_ODT];
    fw_xcp_entry entry[FW_XCP_MAX_ENTRIES];
    /* The running lists compiled when one starts: each ODT's entries as runs
     * of bytes contiguous in one region (run_off: offset, bit 15 set for the
     * calibration page), and the signals they read, refreshed at the event
     * (need_*: bit i for neuron i's weights, health; need_xhat). */
    uint16_t run_off[FW_XCP_MAX_ENTRIES];
    uint8_t run_len[FW_XCP_MAX_ENTRIES];
    uint32_t need_weights;
    uint32_t need_health;
    uint8_t need_xhat;
    uint8_t deferred;                   /* fw_xcp_set_deferred */
    uint8_t pending;                    /* a step event's sample not sent yet (deferred) */
    uint64_t pending_ns;                /* its Measurement's reception time */
    uint8_t last_error;                 /* XCP code of the last error packet (0: none) */
    uint8_t pkt[FW_XCP_MAX_DTO];        /* the packet being built (response or DTO) */
} fw_xcp;

/* Set up the slave (not connected, everything locked, no DAQ). FW_E_NULL,
 * FW_E_CONFIG when a region does not lie within 4 GiB above address_base or
 * the transport has no send. */
fw_status fw_xcp_init(fw_xcp *x, const fw_xcp_config *cfg);

/* Hook the slave into the application: its step event and the calibration
 * hand-over (fw_app_set_step_hooks), and fill the signals once. FW_E_CONFIG
 * when a neuron has more than FW_XCP_TERMS terms. */
fw_status fw_xcp_attach(fw_xcp *x, fw_app *app);

/* Handle one command packet (CTO, without the transport header), sent at
 * now_ns on the application's clock; the response goes out through the
 * transport. FW_OK when answered positively, FW_E_RANGE when answered with
 * an error packet, FW_E_STATE when ignored (not connected), FW_E_HAL when
 * the response could not be sent, FW_E_NULL, FW_E_NOT_INIT. */
fw_status fw_xcp_on_command(fw_xcp *x, fw_app *app, const uint8_t *cto, size_t len, uint64_t now_ns);

/* Where the step event's DAQ sample is built and sent. Off (the default):
 * inside the step event, so inside the Measurement's fw_app_on_frame.
 * On: the step event only notes the sample (its time); the signals are
 * refreshed and the DTOs built and sent by the next fw_xcp_poll, which the
 * platform calls once the frame is handled (its main loop), or at the
 * latest before the next frame is handled (the before_frame hook): either
 * way before anything can change the identifier, so the sample holds the
 * same values and timestamp as one sent inside the event. The frame's
 * deadline then carries none of the DAQ work. FW_E_NULL, FW_E_NOT_INIT. */
fw_status fw_xcp_set_deferred(fw_xcp *x, int on);

/* Send the noted DAQ sample, if any (deferred mode): FW_OK, also when there
 * is none. FW_E_NULL, FW_E_NOT_INIT. */
fw_status fw_xcp_poll(fw_xcp *x, fw_app *app);

/* The XCP error code of the last error packet sent (0 when none). */
uint8_t fw_xcp_last_error(const fw_xcp *x);

#ifdef __cplusplus
}
#endif

#endif /* FW_XCP_H */
