/*
 * fw_secoc_key.h - the AES-128 key of the command authentication (fw_secoc.h),
 * provisioned at build time.
 *
 * THE KEY BELOW IS A PUBLIC TEST KEY, NOT A SECRET: it is the ASCII string
 * "pyrhonn-TEST-key", committed so that the simulations (the Python twin,
 * the Linux runner, the tests, the fuzzer) and their rig (pyrhonn.firmware,
 * hil) agree. Anyone with this repository can command a build that uses it.
 *
 * A real device gets its own key: generate 16 random bytes on a trusted
 * machine, write them into a header outside the repository that defines
 * FW_SECOC_KEY_BYTES and FW_SECOC_KEY_IS_TEST_KEY 0, and compile with
 * -DFW_SECOC_KEY_HEADER='"path/to/that_key.h"'. The rig must hold the same
 * key (pyrhonn.firmware.SecOCSender(key=...)). Better still, a target with a
 * key store (an HSM, or a SHE/crypto peripheral) keeps the key there and
 * computes the CMAC behind fw_cmac's interface.
 */
#ifndef FW_SECOC_KEY_H
#define FW_SECOC_KEY_H

#ifdef FW_SECOC_KEY_HEADER
#include FW_SECOC_KEY_HEADER
#else
/* "pyrhonn-TEST-key" */
#define FW_SECOC_KEY_BYTES                                                                             \
    {                                                                                                  \
        0x70, 0x79, 0x72, 0x68, 0x6f, 0x6e, 0x6e, 0x2d, 0x54, 0x45, 0x53, 0x54, 0x2d, 0x6b, 0x65, 0x79 \
    }
#define FW_SECOC_KEY_IS_TEST_KEY 1
#endif

#endif /* FW_SECOC_KEY_H */
