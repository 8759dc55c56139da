/* code_version.h: how often a material's JIT code changed, in a form that
 * dr.freeze sees (diffraction.cpp).
 *
 * A dr.freeze-d function replays a recording while its inputs keep their
 * layout: Dr.Jit compares their types, whether each is a literal, their
 * gradients, not their sizes. The programs' constants (table offsets and
 * reaches, the built values) are part of the kernels a render records, so
 * a material whose programs changed (a rebuild, or the built parameters'
 * programs coming into or out of use) must change its layout: it counts
 * the changes and its traversal shows the count as the types of 32 markers
 * (bit k set: marker k is a UInt32, else a Float).
 */
#pragma once

#include <drjit/traversable_base.h>

#include <cstdint>

NAMESPACE_BEGIN(mitsuba)
NAMESPACE_BEGIN(diffraction_detail)

template <typename Float> class CodeVersion {
public:
    using UInt32 = dr::uint32_array_t<Float>;

    /// The material's code changed
    void bump() { ++m_count; }

    /// The markers, as a traversal of members (traverse_1_cb_ro / _rw)
    void traverse_ro(void *payload, drjit::detail::traverse_callback_ro fn) const {
        for (uint32_t k = 0; k < 32; ++k) {
            if ((m_count >> k) & 1u) {
                DR_TRAVERSE_MEMBER_RO(m_one)
            } else {
                DR_TRAVERSE_MEMBER_RO(m_zero)
            }
        }
    }
    void traverse_rw(void *payload, drjit::detail::traverse_callback_rw fn) {
        for (uint32_t k = 0; k < 32; ++k) {
            if ((m_count >> k) & 1u) {
                DR_TRAVERSE_MEMBER_RW(m_one)
            } else {
                DR_TRAVERSE_MEMBER_RW(m_zero)
            }
        }
    }

private:
    uint32_t m_count = 0;
    Float m_zero = 0.f;
    UInt32 m_one = 0u;
};

NAMESPACE_END(diffraction_detail)
NAMESPACE_END(mitsuba)

/// Mitsuba's MI_TRAVERSE_CB(Base, members...), then the CodeVersion `version`
#define MI_TRAVERSE_CB_WITH_VERSION(Base, version, ...)                                   \
public:                                                                                    \
    void traverse_1_cb_ro(void *payload, drjit::detail::traverse_callback_ro fn)           \
        const override {                                                                   \
        if (!jit_flag(JitFlag::EnableObjectTraversal))                                     \
            return;                                                                        \
        Base::traverse_1_cb_ro(payload, fn);                                               \
        DRJIT_MAP(DR_TRAVERSE_MEMBER_RO, __VA_ARGS__)                                      \
        version.traverse_ro(payload, fn);                                                  \
    }                                                                                      \
    void traverse_1_cb_rw(void *payload, drjit::detail::traverse_callback_rw fn) override { \
        if (!jit_flag(JitFlag::EnableObjectTraversal))                                     \
            return;                                                                        \
        Base::traverse_1_cb_rw(payload, fn);                                               \
        DRJIT_MAP(DR_TRAVERSE_MEMBER_RW, __VA_ARGS__)                                      \
        version.traverse_rw(payload, fn);                                                  \
    }
