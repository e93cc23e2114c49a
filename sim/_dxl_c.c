/* The emulated bus's compiled packet path (optional: sim/dxl_fast.py falls back to
 * pure Python, byte for byte the same, when this module was not built).
 *
 * crc16: CRC-16/BUYPASS (polynomial 0x8005, initial value 0, no reflection), the CRC
 * of Dynamixel Protocol 2.0 (ROBOTIS e-Manual, "Protocol 2.0", CRC).
 * answer_fast_read: a Fast Sync Read reply's ERR bytes, data and running CRCs, in
 * place, after checking every servo answers normally (awake, at the packet's baud,
 * Status Return Level not 0) and counting the read on each.
 * mark_heard: a broadcast heard by every servo at the packet's baud.
 * goals_heard: whether every servo hears a Sync Write, and how many goals lie outside
 * their limits.
 * write_goals: a Sync Write of Goal Position, each servo as EmulatedServo.write's hot
 * path does it (sim/dxl_servo.py); a servo outside that path gets EmulatedServo.write.
 * line_baud: the speed constant of a tty's termios (tcgetattr, then cfgetospeed).
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <stdint.h>
#include <string.h>
#include <termios.h>

/* X-series control table addresses (ROBOTIS e-Manual) and sim/dxl_servo.py's values */
enum {
    A_BAUD_RATE = 8, A_OPERATING_MODE = 11, A_MOVING_THRESHOLD = 24, A_MAX_POSITION = 48,
    A_MIN_POSITION = 52, A_TORQUE_ENABLE = 64, A_STATUS_RETURN_LEVEL = 68,
    A_HARDWARE_ERROR = 70, A_BUS_WATCHDOG = 98, A_PROFILE_VELOCITY = 112,
    A_GOAL_POSITION = 116, A_MOVING_STATUS = 123, A_PRESENT_POSITION = 132,
};
#define GOAL_MIN (-1048575L)
#define GOAL_MAX 1048575L
#define IN_POSITION 0x01
#define PROFILE_ONGOING 0x02

static uint16_t crc_table[256];

static void make_table(void) {
    for (unsigned i = 0; i < 256; i++) {
        uint16_t crc = (uint16_t)(i << 8);
        for (int b = 0; b < 8; b++)
            crc = (crc & 0x8000) ? (uint16_t)((crc << 1) ^ 0x8005) : (uint16_t)(crc << 1);
        crc_table[i] = crc;
    }
}

static inline uint16_t crc_update(uint16_t crc, const uint8_t *p, Py_ssize_t n) {
    for (Py_ssize_t i = 0; i < n; i++)
        crc = (uint16_t)((crc << 8) ^ crc_table[(crc >> 8) ^ p[i]]);
    return crc;
}

static PyObject *py_crc16(PyObject *self, PyObject *args) {
    Py_buffer data;
    unsigned int crc = 0;
    if (!PyArg_ParseTuple(args, "y*|I:crc16", &data, &crc))
        return NULL;
    uint16_t out = crc_update((uint16_t)crc, (const uint8_t *)data.buf, data.len);
    PyBuffer_Release(&data);
    return PyLong_FromUnsignedLong(out);
}

static PyObject *s_last_heard, *s_counters, *s_profile_type, *s_trajectory_ticks, *s_write,
    *s_writes, *s_one, *s_silent_until, *s_reads;

static int fill(Py_buffer *reply, PyObject *seq, Py_ssize_t address, Py_ssize_t length,
                Py_ssize_t prefix, Py_ssize_t error_address, unsigned int alert);
static int count_one(PyObject *servo, PyObject *key);

/* fill(reply, mems, ...): for servo k (mems[k], a bytes-like control table) the chunk
 * starts at prefix + k * (length + 4): ERR (alert when mems[k][error_address] is set,
 * else 0), ID (left as it is), the length bytes at address, then the running CRC of
 * the reply from its first byte, little-endian. */
static int fill(Py_buffer *reply, PyObject *seq, Py_ssize_t address, Py_ssize_t length,
                Py_ssize_t prefix, Py_ssize_t error_address, unsigned int alert) {
    Py_ssize_t count = PySequence_Fast_GET_SIZE(seq);
    Py_ssize_t stride = length + 4;
    uint8_t *out = (uint8_t *)reply->buf;
    if (address < 0 || length < 0 || prefix < 0 || error_address < 0
            || prefix + count * stride > reply->len) {
        PyErr_SetString(PyExc_ValueError, "answer_fast_read: the reply is too short");
        return -1;
    }
    for (Py_ssize_t k = 0; k < count; k++) {
        Py_buffer mem;
        if (PyObject_GetBuffer(PySequence_Fast_GET_ITEM(seq, k), &mem, PyBUF_SIMPLE) < 0)
            return -1;
        if (address + length > mem.len || error_address >= mem.len) {
            PyBuffer_Release(&mem);
            PyErr_SetString(PyExc_ValueError, "answer_fast_read: a control table is too short");
            return -1;
        }
        const uint8_t *m = (const uint8_t *)mem.buf;
        uint8_t *chunk = out + prefix + k * stride;
        chunk[0] = m[error_address] ? (uint8_t)alert : 0;
        memcpy(chunk + 2, m + address, (size_t)length);
        PyBuffer_Release(&mem);
    }
    uint16_t crc = 0;
    Py_ssize_t start = 0;
    for (Py_ssize_t k = 0; k < count; k++) {
        Py_ssize_t end = prefix + (k + 1) * stride - 2;
        crc = crc_update(crc, out + start, end - start);
        out[end] = (uint8_t)(crc & 0xFF);
        out[end + 1] = (uint8_t)(crc >> 8);
        start = end;
    }
    return 0;
}

static inline int32_t i32(const uint8_t *p) {
    return (int32_t)((uint32_t)p[0] | (uint32_t)p[1] << 8 | (uint32_t)p[2] << 16
                     | (uint32_t)p[3] << 24);
}

static inline uint32_t u32(const uint8_t *p) {
    return (uint32_t)p[0] | (uint32_t)p[1] << 8 | (uint32_t)p[2] << 16 | (uint32_t)p[3] << 24;
}

static int position_mode(uint8_t mode) { return mode == 3 || mode == 4 || mode == 5; }

/* One servo's Goal Position write on the hot path; 1 done, 0 not on it, -1 error. */
static int hot_goal(PyObject *servo, uint8_t *m, const uint8_t *data) {
    uint8_t mode = m[A_OPERATING_MODE];
    if (m[A_BUS_WATCHDOG] == 0xFF || !position_mode(mode))
        return 0;
    int32_t value = i32(data);
    int ok = mode != 3 ? (value >= GOAL_MIN && value <= GOAL_MAX)
                       : (i32(m + A_MIN_POSITION) <= value && value <= i32(m + A_MAX_POSITION));
    if (!ok)
        return 0;
    if (count_one(servo, s_writes) < 0)
        return -1;
    memcpy(m + A_GOAL_POSITION, data, 4);
    /* Moving Status (sim/dxl_servo.py, _publish_moving_status) */
    PyObject *ptype = PyObject_GetAttr(servo, s_profile_type);
    if (ptype == NULL)
        return -1;
    long status = PyLong_AsLong(ptype);
    Py_DECREF(ptype);
    if (status == -1 && PyErr_Occurred())
        return -1;
    int ongoing = 0;
    if (u32(m + A_PROFILE_VELOCITY) != 0) {
        PyObject *traj = PyObject_GetAttr(servo, s_trajectory_ticks);
        if (traj == NULL)
            return -1;
        double t = PyFloat_AsDouble(traj);
        Py_DECREF(traj);
        if (t == -1.0 && PyErr_Occurred())
            return -1;
        ongoing = t != (double)value;
    }
    if (ongoing && m[A_TORQUE_ENABLE]) {
        status |= PROFILE_ONGOING;
    } else if (m[A_TORQUE_ENABLE]) {
        int64_t off = (int64_t)value - (int64_t)i32(m + A_PRESENT_POSITION);
        if (off < 0)
            off = -off;
        if (off <= (int64_t)u32(m + A_MOVING_THRESHOLD))
            status |= IN_POSITION;
    }
    m[A_MOVING_STATUS] = (uint8_t)status;
    return 1;
}

/* servos and mems as fast sequences (new references in *sseq and *mseq, NULL where not
 * made) of one length: that length, or -1 with the exception set (naming ``who``). */
static Py_ssize_t servo_tables(PyObject *servos, PyObject *mems, const char *who,
                               PyObject **sseq, PyObject **mseq) {
    *sseq = PySequence_Fast(servos, "servos must be a sequence");
    *mseq = *sseq == NULL ? NULL : PySequence_Fast(mems, "mems must be a sequence");
    if (*mseq == NULL)
        return -1;
    Py_ssize_t count = PySequence_Fast_GET_SIZE(*sseq);
    if (PySequence_Fast_GET_SIZE(*mseq) != count) {
        PyErr_Format(PyExc_ValueError, "%s: servos and mems disagree", who);
        return -1;
    }
    return count;
}

/* write_goals(servos, mems, body, now): body is the Sync Write's ``ID goal(4)`` items,
 * one per servo in order; each servo is heard (last_heard = now) and written. */
static PyObject *py_write_goals(PyObject *self, PyObject *args) {
    PyObject *servos, *mems, *now;
    Py_buffer body;
    if (!PyArg_ParseTuple(args, "OOy*O!:write_goals", &servos, &mems, &body, &PyFloat_Type,
                          &now))
        return NULL;
    PyObject *sseq, *mseq;
    Py_ssize_t count = servo_tables(servos, mems, "write_goals", &sseq, &mseq);
    if (count < 0)
        goto fail;
    if (body.len != count * 5) {
        PyErr_SetString(PyExc_ValueError, "write_goals: servos, mems and body disagree");
        goto fail;
    }
    const uint8_t *items = (const uint8_t *)body.buf;
    for (Py_ssize_t k = 0; k < count; k++) {
        PyObject *servo = PySequence_Fast_GET_ITEM(sseq, k);
        const uint8_t *data = items + k * 5 + 1;
        if (PyObject_SetAttr(servo, s_last_heard, now) < 0)
            goto fail;
        Py_buffer mem;
        if (PyObject_GetBuffer(PySequence_Fast_GET_ITEM(mseq, k), &mem, PyBUF_WRITABLE) < 0)
            goto fail;
        int done = mem.len > A_PRESENT_POSITION + 3 ? hot_goal(servo, (uint8_t *)mem.buf, data)
                                                    : 0;
        PyBuffer_Release(&mem);
        if (done < 0)
            goto fail;
        if (!done) {
            PyObject *addr = PyLong_FromLong(A_GOAL_POSITION);
            PyObject *val = PyBytes_FromStringAndSize((const char *)data, 4);
            PyObject *res = (addr && val)
                ? PyObject_CallMethodObjArgs(servo, s_write, addr, val, NULL) : NULL;
            Py_XDECREF(addr);
            Py_XDECREF(val);
            if (res == NULL)
                goto fail;
            Py_DECREF(res);
        }
    }
    Py_DECREF(sseq);
    Py_DECREF(mseq);
    PyBuffer_Release(&body);
    Py_RETURN_NONE;
fail:
    Py_XDECREF(sseq);
    Py_XDECREF(mseq);
    PyBuffer_Release(&body);
    return NULL;
}

/* Whether the servo is awake (silent_until <= now) and hears ``baud_index`` (-1: any);
 * 1 yes, 0 no, -1 error. */
static int hears(PyObject *servo, const uint8_t *m, double now, long baud_index) {
    PyObject *until = PyObject_GetAttr(servo, s_silent_until);
    if (until == NULL)
        return -1;
    double t = PyFloat_AsDouble(until);
    Py_DECREF(until);
    if (t == -1.0 && PyErr_Occurred())
        return -1;
    return !(t > now) && (baud_index < 0 || m[A_BAUD_RATE] == baud_index);
}

/* A servo's control table, checked long enough for every address used here. */
static int table(PyObject *obj, Py_buffer *mem, int flags) {
    if (PyObject_GetBuffer(obj, mem, flags) < 0)
        return -1;
    if (mem->len <= A_PRESENT_POSITION + 3) {
        PyBuffer_Release(mem);
        PyErr_SetString(PyExc_ValueError, "a control table is too short");
        return -1;
    }
    return 0;
}

static int count_one(PyObject *servo, PyObject *key) {
    PyObject *counters = PyObject_GetAttr(servo, s_counters);
    if (counters == NULL)
        return -1;
    PyObject *was = PyDict_GetItemWithError(counters, key);
    PyObject *more = was == NULL ? NULL : PyNumber_Add(was, s_one);
    int set = more == NULL ? -1 : PyDict_SetItem(counters, key, more);
    Py_XDECREF(more);
    Py_DECREF(counters);
    if (set < 0 && !PyErr_Occurred())
        PyErr_SetObject(PyExc_KeyError, key);
    return set;
}

/* answer_fast_read(reply, servos, mems, address, length, prefix, error_address, alert,
 * now, baud_index) -> bool: False (nothing done) when a servo would not answer normally
 * (asleep, at another baud, Status Return Level 0); else each servo heard at ``now``,
 * its read counted, and the reply filled (fill, above). */
static PyObject *py_answer_fast_read(PyObject *self, PyObject *args) {
    Py_buffer reply;
    PyObject *servos, *mems, *now;
    Py_ssize_t address, length, prefix, error_address;
    unsigned int alert;
    long baud_index;
    if (!PyArg_ParseTuple(args, "w*OOnnnnIO!l:answer_fast_read", &reply, &servos, &mems,
                          &address, &length, &prefix, &error_address, &alert, &PyFloat_Type,
                          &now, &baud_index))
        return NULL;
    double t = PyFloat_AS_DOUBLE(now);
    PyObject *result = NULL;
    PyObject *sseq, *mseq;
    Py_ssize_t count = servo_tables(servos, mems, "answer_fast_read", &sseq, &mseq);
    if (count < 0)
        goto done;
    for (Py_ssize_t k = 0; k < count; k++) {
        Py_buffer mem;
        if (table(PySequence_Fast_GET_ITEM(mseq, k), &mem, PyBUF_SIMPLE) < 0)
            goto done;
        const uint8_t *m = (const uint8_t *)mem.buf;
        int ok = hears(PySequence_Fast_GET_ITEM(sseq, k), m, t, baud_index);
        uint8_t level = m[A_STATUS_RETURN_LEVEL];
        PyBuffer_Release(&mem);
        if (ok < 0)
            goto done;
        if (!ok || !level) {
            result = Py_NewRef(Py_False);
            goto done;
        }
    }
    for (Py_ssize_t k = 0; k < count; k++) {
        PyObject *servo = PySequence_Fast_GET_ITEM(sseq, k);
        if (PyObject_SetAttr(servo, s_last_heard, now) < 0 || count_one(servo, s_reads) < 0)
            goto done;
    }
    if (fill(&reply, mseq, address, length, prefix, error_address, alert) < 0)
        goto done;
    result = Py_NewRef(Py_True);
done:
    Py_XDECREF(sseq);
    Py_XDECREF(mseq);
    PyBuffer_Release(&reply);
    return result;
}

/* goals_heard(servos, mems, body, now, baud_index, low, high) -> int: -1 when a servo
 * does not hear the Sync Write (asleep, another baud); else how many goals of ``body``
 * (``ID goal(4)`` items) lie outside [low[k], high[k]] (low > high: no limits). */
static PyObject *py_goals_heard(PyObject *self, PyObject *args) {
    PyObject *servos, *mems, *low, *high;
    Py_buffer body;
    double now;
    long baud_index;
    if (!PyArg_ParseTuple(args, "OOy*dlOO:goals_heard", &servos, &mems, &body, &now,
                          &baud_index, &low, &high))
        return NULL;
    PyObject *result = NULL;
    PyObject *sseq = PySequence_Fast(servos, "servos must be a sequence");
    PyObject *mseq = sseq == NULL ? NULL : PySequence_Fast(mems, "mems must be a sequence");
    PyObject *lseq = mseq == NULL ? NULL : PySequence_Fast(low, "low must be a sequence");
    PyObject *hseq = lseq == NULL ? NULL : PySequence_Fast(high, "high must be a sequence");
    if (hseq == NULL)
        goto done;
    Py_ssize_t count = PySequence_Fast_GET_SIZE(sseq);
    if (PySequence_Fast_GET_SIZE(mseq) != count || PySequence_Fast_GET_SIZE(lseq) != count
            || PySequence_Fast_GET_SIZE(hseq) != count || body.len != count * 5) {
        PyErr_SetString(PyExc_ValueError, "goals_heard: the plan and the body disagree");
        goto done;
    }
    for (Py_ssize_t k = 0; k < count; k++) {
        Py_buffer mem;
        if (table(PySequence_Fast_GET_ITEM(mseq, k), &mem, PyBUF_SIMPLE) < 0)
            goto done;
        int ok = hears(PySequence_Fast_GET_ITEM(sseq, k), (const uint8_t *)mem.buf, now,
                       baud_index);
        PyBuffer_Release(&mem);
        if (ok < 0)
            goto done;
        if (!ok) {
            result = PyLong_FromLong(-1);
            goto done;
        }
    }
    long outside = 0;
    const uint8_t *items = (const uint8_t *)body.buf;
    for (Py_ssize_t k = 0; k < count; k++) {
        long lo = PyLong_AsLong(PySequence_Fast_GET_ITEM(lseq, k));
        long hi = PyLong_AsLong(PySequence_Fast_GET_ITEM(hseq, k));
        if (PyErr_Occurred())
            goto done;
        long goal = i32(items + k * 5 + 1);
        outside += lo <= hi && !(lo <= goal && goal <= hi);
    }
    result = PyLong_FromLong(outside);
done:
    Py_XDECREF(sseq);
    Py_XDECREF(mseq);
    Py_XDECREF(lseq);
    Py_XDECREF(hseq);
    PyBuffer_Release(&body);
    return result;
}

/* mark_heard(servos, mems, now, baud_index): a broadcast heard at ``now`` by every servo
 * at ``baud_index`` (-1: all; any other negative value: none). */
static PyObject *py_mark_heard(PyObject *self, PyObject *args) {
    PyObject *servos, *mems, *now;
    long baud_index;
    if (!PyArg_ParseTuple(args, "OOO!l:mark_heard", &servos, &mems, &PyFloat_Type, &now,
                          &baud_index))
        return NULL;
    PyObject *result = NULL;
    PyObject *sseq, *mseq;
    Py_ssize_t count = servo_tables(servos, mems, "mark_heard", &sseq, &mseq);
    if (count < 0)
        goto done;
    for (Py_ssize_t k = 0; k < count; k++) {
        Py_buffer mem;
        if (table(PySequence_Fast_GET_ITEM(mseq, k), &mem, PyBUF_SIMPLE) < 0)
            goto done;
        int heard = baud_index == -1
            || (baud_index >= 0 && ((const uint8_t *)mem.buf)[A_BAUD_RATE] == baud_index);
        PyBuffer_Release(&mem);
        if (heard && PyObject_SetAttr(PySequence_Fast_GET_ITEM(sseq, k), s_last_heard, now) < 0)
            goto done;
    }
    result = Py_NewRef(Py_None);
done:
    Py_XDECREF(sseq);
    Py_XDECREF(mseq);
    return result;
}

/* line_baud(fd) -> int: the output speed constant (termios B...) the tty is set to. */
static PyObject *py_line_baud(PyObject *self, PyObject *args) {
    int fd;
    if (!PyArg_ParseTuple(args, "i:line_baud", &fd))
        return NULL;
    struct termios mode;
    if (tcgetattr(fd, &mode) < 0)
        return PyErr_SetFromErrno(PyExc_OSError);
    return PyLong_FromUnsignedLong((unsigned long)cfgetospeed(&mode));
}

static PyMethodDef methods[] = {
    {"crc16", py_crc16, METH_VARARGS,
     "crc16(data, crc=0) -> int: CRC-16/BUYPASS of data, continuing from crc."},
    {"answer_fast_read", py_answer_fast_read, METH_VARARGS,
     "answer_fast_read(reply, servos, mems, address, length, prefix, error_address, alert, "
     "now, baud_index) -> bool: a Fast Sync Read reply when every servo answers normally."},
    {"goals_heard", py_goals_heard, METH_VARARGS,
     "goals_heard(servos, mems, body, now, baud_index, low, high) -> int: -1 when a servo "
     "does not hear the Sync Write, else how many goals lie outside their limits."},
    {"mark_heard", py_mark_heard, METH_VARARGS,
     "mark_heard(servos, mems, now, baud_index): a broadcast heard at now by every servo at "
     "baud_index (-1: all)."},
    {"line_baud", py_line_baud, METH_VARARGS,
     "line_baud(fd) -> int: the termios output speed constant of the tty fd."},
    {"write_goals", py_write_goals, METH_VARARGS,
     "write_goals(servos, mems, body, now): a Sync Write of Goal Position (``ID goal`` "
     "items), each servo heard and written as EmulatedServo.write does."},
    {NULL, NULL, 0, NULL},
};

static struct PyModuleDef module = {
    PyModuleDef_HEAD_INIT, "sim._dxl_c",
    "The emulated bus's compiled packet path (sim/dxl_fast.py: CRC-16/BUYPASS, the Fast "
    "Sync Read reply, the Goal Position Sync Write).",
    -1, methods, NULL, NULL, NULL, NULL,
};

PyMODINIT_FUNC PyInit__dxl_c(void) {
    make_table();
    s_last_heard = PyUnicode_InternFromString("last_heard");
    s_counters = PyUnicode_InternFromString("counters");
    s_profile_type = PyUnicode_InternFromString("_profile_type");
    s_trajectory_ticks = PyUnicode_InternFromString("trajectory_ticks");
    s_write = PyUnicode_InternFromString("write");
    s_writes = PyUnicode_InternFromString("writes");
    s_one = PyLong_FromLong(1);
    s_silent_until = PyUnicode_InternFromString("silent_until");
    s_reads = PyUnicode_InternFromString("reads");
    if (!s_last_heard || !s_counters || !s_profile_type || !s_trajectory_ticks || !s_write
            || !s_writes || !s_one || !s_silent_until || !s_reads)
        return NULL;
    return PyModule_Create(&module);
}
