/* Golden vectors for the seed 000 AMR SPI frame from the nanopb C library: MotorCommand, MotorFeedback
 * and McuInfo (which carries info_version in place of protocol_version).
 *
 *   nanopb_amr encode CASES          prints one frame per case line (nanopb encoder, seed CRC loop)
 *   nanopb_amr check CASES FRAMES    decodes FRAMES with nanopb, compares with CASES, exit 1 on mismatch
 *
 * Build (see run.sh): nanopb_generator.py -f ../proto/amr.options ../proto/amr.proto, then
 * gcc nanopb_amr.c amr.pb.c -lprotobuf-nanopb.
 */
#include <inttypes.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include <pb_decode.h>
#include <pb_encode.h>

#include "amr.pb.h"

#define FRAME_LEN 64
#define CRC_OFFSET (FRAME_LEN - 2)
#define PROTOCOL_VERSION 1
#define INFO_VERSION 1

enum kind { COMMAND, FEEDBACK, INFO };

static enum kind kind_of(const char *line) {
    if (strncmp(line, "command", 7) == 0) return COMMAND;
    if (strncmp(line, "feedback", 8) == 0) return FEEDBACK;
    if (strncmp(line, "info", 4) == 0) return INFO;
    fprintf(stderr, "unknown kind in %s\n", line);
    exit(2);
}

static const char *const KIND_NAMES[] = {"command", "feedback", "info"};

/* The seed's CRC-16/CCITT loop, unchanged. */
static uint16_t crc16_ccitt(const uint8_t *data, size_t len) {
    uint16_t crc = 0xFFFF;
    for (size_t i = 0; i < len; i++) {
        crc ^= (uint16_t)data[i] << 8;
        for (int j = 0; j < 8; j++) {
            if (crc & 0x8000)
                crc = (crc << 1) ^ 0x1021;
            else
                crc <<= 1;
        }
    }
    return crc;
}

static float bits_to_float(uint32_t b) {
    float f;
    memcpy(&f, &b, sizeof f);
    return f;
}

static uint32_t float_to_bits(float f) {
    uint32_t b;
    memcpy(&b, &f, sizeof b);
    return b;
}

/* Reads "key=value" from a case line. */
static int64_t field(const char *line, const char *key) {
    char pat[64];
    snprintf(pat, sizeof pat, " %s=", key);
    const char *p = strstr(line, pat);
    if (!p) {
        fprintf(stderr, "missing %s in %s\n", key, line);
        exit(2);
    }
    return strtoll(p + strlen(pat), NULL, 10);
}

static void parse_command(const char *line, amr_MotorCommand *m) {
    *m = (amr_MotorCommand)amr_MotorCommand_init_zero;
    m->timestamp_us = (uint32_t)field(line, "timestamp_us");
    m->left_speed_cmd = bits_to_float((uint32_t)field(line, "left_speed_cmd"));
    m->right_speed_cmd = bits_to_float((uint32_t)field(line, "right_speed_cmd"));
    m->control_mode = (uint8_t)field(line, "control_mode");
    m->enable = (uint8_t)field(line, "enable");
    m->seq = (uint32_t)field(line, "seq");
    m->protocol_version = PROTOCOL_VERSION;
    m->request = (uint32_t)field(line, "request");
}

static void parse_feedback(const char *line, amr_MotorFeedback *m) {
    *m = (amr_MotorFeedback)amr_MotorFeedback_init_zero;
    m->timestamp_us = (uint32_t)field(line, "timestamp_us");
    m->left_speed = bits_to_float((uint32_t)field(line, "left_speed"));
    m->right_speed = bits_to_float((uint32_t)field(line, "right_speed"));
    m->left_current = bits_to_float((uint32_t)field(line, "left_current"));
    m->right_current = bits_to_float((uint32_t)field(line, "right_current"));
    m->left_encoder = (int32_t)field(line, "left_encoder");
    m->right_encoder = (int32_t)field(line, "right_encoder");
    m->fault_flags = (uint16_t)field(line, "fault_flags");
    m->seq = (uint32_t)field(line, "seq");
    m->mode = (uint8_t)field(line, "mode");
    m->cmd_seq = (uint32_t)field(line, "cmd_seq");
    m->protocol_version = PROTOCOL_VERSION;
}

static void parse_info(const char *line, amr_McuInfo *m) {
    *m = (amr_McuInfo)amr_McuInfo_init_zero;
    m->info_version = INFO_VERSION;
    m->fw_version = (uint32_t)field(line, "fw_version");
    m->git_hash = (uint32_t)field(line, "git_hash");
    m->board = (uint8_t)field(line, "board");
    m->build_date = (uint32_t)field(line, "build_date");
    m->reset_cause = (uint8_t)field(line, "reset_cause");
    m->reset_count = (uint32_t)field(line, "reset_count");
    m->panic_line = (uint32_t)field(line, "panic_line");
    m->seq = (uint32_t)field(line, "seq");
    m->dirty = field(line, "dirty") != 0;
}

static void print_frame(const char *kind, const uint8_t *frame) {
    printf("%s ", kind);
    for (int i = 0; i < FRAME_LEN; i++) printf("%02x", frame[i]);
    printf("\n");
}

static int encode_case(const char *line, uint8_t *frame) {
    memset(frame, 0, FRAME_LEN);
    pb_ostream_t os = pb_ostream_from_buffer(frame + 1, CRC_OFFSET - 1);
    int ok;
    if (kind_of(line) == COMMAND) {
        amr_MotorCommand m;
        parse_command(line, &m);
        ok = pb_encode(&os, amr_MotorCommand_fields, &m);
    } else if (kind_of(line) == FEEDBACK) {
        amr_MotorFeedback m;
        parse_feedback(line, &m);
        ok = pb_encode(&os, amr_MotorFeedback_fields, &m);
    } else {
        amr_McuInfo m;
        parse_info(line, &m);
        ok = pb_encode(&os, amr_McuInfo_fields, &m);
    }
    if (!ok) {
        fprintf(stderr, "encode failed: %s\n", PB_GET_ERROR(&os));
        return 0;
    }
    frame[0] = (uint8_t)os.bytes_written;
    uint16_t crc = crc16_ccitt(frame, CRC_OFFSET);
    frame[CRC_OFFSET] = crc >> 8;
    frame[CRC_OFFSET + 1] = crc & 0xFF;
    return 1;
}

static int hex_frame(const char *hex, uint8_t *frame) {
    if (strlen(hex) < 2 * FRAME_LEN) return 0;
    for (int i = 0; i < FRAME_LEN; i++) {
        unsigned v;
        if (sscanf(hex + 2 * i, "%2x", &v) != 1) return 0;
        frame[i] = (uint8_t)v;
    }
    return 1;
}

/* Decodes a frame with nanopb and compares it with the case; returns 1 if equal. */
static int check_case(const char *line, const uint8_t *frame) {
    uint16_t crc = crc16_ccitt(frame, CRC_OFFSET);
    if (((frame[CRC_OFFSET] << 8) | frame[CRC_OFFSET + 1]) != crc) {
        fprintf(stderr, "crc mismatch\n");
        return 0;
    }
    size_t n = frame[0];
    if (n > CRC_OFFSET - 1) return 0;
    for (size_t i = 1 + n; i < CRC_OFFSET; i++)
        if (frame[i] != 0) return 0;
    pb_istream_t is = pb_istream_from_buffer(frame + 1, n);
    if (kind_of(line) == COMMAND) {
        amr_MotorCommand want, got = amr_MotorCommand_init_zero;
        parse_command(line, &want);
        if (!pb_decode(&is, amr_MotorCommand_fields, &got)) {
            fprintf(stderr, "decode failed: %s\n", PB_GET_ERROR(&is));
            return 0;
        }
        return got.timestamp_us == want.timestamp_us &&
               float_to_bits(got.left_speed_cmd) == float_to_bits(want.left_speed_cmd) &&
               float_to_bits(got.right_speed_cmd) == float_to_bits(want.right_speed_cmd) &&
               got.control_mode == want.control_mode && got.enable == want.enable && got.seq == want.seq &&
               got.protocol_version == PROTOCOL_VERSION && got.request == want.request;
    } else if (kind_of(line) == FEEDBACK) {
        amr_MotorFeedback want, got = amr_MotorFeedback_init_zero;
        parse_feedback(line, &want);
        if (!pb_decode(&is, amr_MotorFeedback_fields, &got)) {
            fprintf(stderr, "decode failed: %s\n", PB_GET_ERROR(&is));
            return 0;
        }
        return got.timestamp_us == want.timestamp_us &&
               float_to_bits(got.left_speed) == float_to_bits(want.left_speed) &&
               float_to_bits(got.right_speed) == float_to_bits(want.right_speed) &&
               float_to_bits(got.left_current) == float_to_bits(want.left_current) &&
               float_to_bits(got.right_current) == float_to_bits(want.right_current) &&
               got.left_encoder == want.left_encoder && got.right_encoder == want.right_encoder &&
               got.fault_flags == want.fault_flags && got.seq == want.seq && got.mode == want.mode &&
               got.cmd_seq == want.cmd_seq && got.protocol_version == PROTOCOL_VERSION;
    } else {
        amr_McuInfo want, got = amr_McuInfo_init_zero;
        parse_info(line, &want);
        if (!pb_decode(&is, amr_McuInfo_fields, &got)) {
            fprintf(stderr, "decode failed: %s\n", PB_GET_ERROR(&is));
            return 0;
        }
        return got.info_version == INFO_VERSION && got.fw_version == want.fw_version &&
               got.git_hash == want.git_hash && got.board == want.board && got.build_date == want.build_date &&
               got.reset_cause == want.reset_cause && got.reset_count == want.reset_count &&
               got.panic_line == want.panic_line && got.seq == want.seq && got.dirty == want.dirty;
    }
}

int main(int argc, char **argv) {
    if (argc < 3) {
        fprintf(stderr, "usage: %s encode CASES | check CASES FRAMES\n", argv[0]);
        return 2;
    }
    FILE *cases = fopen(argv[2], "r");
    if (!cases) return 2;
    char line[1024], fline[1024];
    uint8_t frame[FRAME_LEN];
    if (strcmp(argv[1], "encode") == 0) {
        fprintf(stderr, "nanopb sizes: amr_MotorCommand_size=%d amr_MotorFeedback_size=%d amr_McuInfo_size=%d\n",
                amr_MotorCommand_size, amr_MotorFeedback_size, amr_McuInfo_size);
        while (fgets(line, sizeof line, cases)) {
            if (!encode_case(line, frame)) return 1;
            print_frame(KIND_NAMES[kind_of(line)], frame);
        }
        return 0;
    }
    if (strcmp(argv[1], "check") == 0 && argc == 4) {
        FILE *frames = fopen(argv[3], "r");
        if (!frames) return 2;
        int n = 0, bad = 0;
        while (fgets(line, sizeof line, cases)) {
            if (!fgets(fline, sizeof fline, frames)) {
                fprintf(stderr, "fewer frames than cases\n");
                return 1;
            }
            const char *hex = strchr(fline, ' ');
            n++;
            if (!hex || !hex_frame(hex + 1, frame) || !check_case(line, frame)) {
                bad++;
                fprintf(stderr, "MISMATCH case %d: %s", n, line);
            }
        }
        printf("amr: nanopb decoded %d frames from %s, %d mismatches\n", n, argv[3], bad);
        return bad ? 1 : 0;
    }
    return 2;
}
