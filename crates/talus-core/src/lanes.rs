//! Four `f64` lanes and three-vectors of them, for hot loops that evaluate four contacts
//! (or four candidate pairs) at once.
//!
//! Every operation is the IEEE operation of its scalar form, lane by lane: additions,
//! subtractions, products, quotients and square roots are correctly rounded, and nothing
//! is fused into a multiply–add. A formula written with these types in the same order as
//! its scalar form (glam's `DVec3` for the vectors) therefore gives the same bits in every
//! lane, which is what lets the lane forms of the contact laws be tested against their
//! scalar forms bit for bit. On x86-64 with AVX (Talus is built for x86-64-v3 there,
//! `.cargo/config.toml`) a value is one 256-bit register; elsewhere it is an array that
//! the compiler may vectorise as it can.

use glam::DVec3;

#[cfg(all(target_arch = "x86_64", target_feature = "avx"))]
mod imp {
    use std::arch::x86_64::*;

    /// Four lanes.
    pub type Raw = __m256d;

    // SAFETY (every block below): the crate is compiled with AVX enabled (the cfg above),
    // so these intrinsics are available on the processors the binary runs on.
    #[inline(always)]
    pub fn splat(x: f64) -> Raw {
        unsafe { _mm256_set1_pd(x) }
    }
    #[inline(always)]
    pub fn from_array(a: [f64; 4]) -> Raw {
        unsafe { _mm256_loadu_pd(a.as_ptr()) }
    }
    #[inline(always)]
    pub fn to_array(x: Raw) -> [f64; 4] {
        let mut out = [0.0; 4];
        unsafe { _mm256_storeu_pd(out.as_mut_ptr(), x) };
        out
    }
    #[inline(always)]
    pub fn add(a: Raw, b: Raw) -> Raw {
        unsafe { _mm256_add_pd(a, b) }
    }
    #[inline(always)]
    pub fn sub(a: Raw, b: Raw) -> Raw {
        unsafe { _mm256_sub_pd(a, b) }
    }
    #[inline(always)]
    pub fn mul(a: Raw, b: Raw) -> Raw {
        unsafe { _mm256_mul_pd(a, b) }
    }
    #[inline(always)]
    pub fn div(a: Raw, b: Raw) -> Raw {
        unsafe { _mm256_div_pd(a, b) }
    }
    #[inline(always)]
    pub fn sqrt(a: Raw) -> Raw {
        unsafe { _mm256_sqrt_pd(a) }
    }
    #[inline(always)]
    pub fn neg(a: Raw) -> Raw {
        unsafe { _mm256_xor_pd(a, _mm256_set1_pd(-0.0)) }
    }
    #[inline(always)]
    pub fn abs(a: Raw) -> Raw {
        unsafe { _mm256_andnot_pd(_mm256_set1_pd(-0.0), a) }
    }
    #[inline(always)]
    pub fn lt(a: Raw, b: Raw) -> Raw {
        unsafe { _mm256_cmp_pd::<_CMP_LT_OQ>(a, b) }
    }
    #[inline(always)]
    pub fn le(a: Raw, b: Raw) -> Raw {
        unsafe { _mm256_cmp_pd::<_CMP_LE_OQ>(a, b) }
    }
    #[inline(always)]
    pub fn eq(a: Raw, b: Raw) -> Raw {
        unsafe { _mm256_cmp_pd::<_CMP_EQ_OQ>(a, b) }
    }
    #[inline(always)]
    pub fn is_finite(a: Raw) -> Raw {
        // x − x is 0 for a finite x and NaN for an infinite or NaN one.
        unsafe { _mm256_cmp_pd::<_CMP_ORD_Q>(_mm256_sub_pd(a, a), _mm256_setzero_pd()) }
    }
    #[inline(always)]
    pub fn and(a: Raw, b: Raw) -> Raw {
        unsafe { _mm256_and_pd(a, b) }
    }
    #[inline(always)]
    pub fn or(a: Raw, b: Raw) -> Raw {
        unsafe { _mm256_or_pd(a, b) }
    }
    #[inline(always)]
    pub fn not(a: Raw) -> Raw {
        unsafe { _mm256_xor_pd(a, _mm256_castsi256_pd(_mm256_set1_epi64x(-1))) }
    }
    #[inline(always)]
    pub fn select(mask: Raw, a: Raw, b: Raw) -> Raw {
        unsafe { _mm256_blendv_pd(b, a, mask) }
    }
    #[inline(always)]
    pub fn bits(mask: Raw) -> u32 {
        unsafe { _mm256_movemask_pd(mask) as u32 }
    }
    #[inline(always)]
    pub fn from_bits(bits: u32) -> Raw {
        let lane = |k: u32| if bits >> k & 1 == 1 { -1i64 } else { 0 };
        unsafe { _mm256_castsi256_pd(_mm256_setr_epi64x(lane(0), lane(1), lane(2), lane(3))) }
    }
}

#[cfg(not(all(target_arch = "x86_64", target_feature = "avx")))]
mod imp {
    /// Four lanes.
    pub type Raw = [f64; 4];

    #[inline(always)]
    fn map(a: Raw, f: impl Fn(f64) -> f64) -> Raw {
        [f(a[0]), f(a[1]), f(a[2]), f(a[3])]
    }
    #[inline(always)]
    fn zip(a: Raw, b: Raw, f: impl Fn(f64, f64) -> f64) -> Raw {
        [f(a[0], b[0]), f(a[1], b[1]), f(a[2], b[2]), f(a[3], b[3])]
    }
    #[inline(always)]
    fn mask(t: bool) -> f64 {
        if t { f64::from_bits(u64::MAX) } else { 0.0 }
    }
    #[inline(always)]
    fn set(x: f64) -> bool {
        x.to_bits() >> 63 == 1
    }
    #[inline(always)]
    pub fn splat(x: f64) -> Raw {
        [x; 4]
    }
    #[inline(always)]
    pub fn from_array(a: [f64; 4]) -> Raw {
        a
    }
    #[inline(always)]
    pub fn to_array(x: Raw) -> [f64; 4] {
        x
    }
    #[inline(always)]
    pub fn add(a: Raw, b: Raw) -> Raw {
        zip(a, b, |x, y| x + y)
    }
    #[inline(always)]
    pub fn sub(a: Raw, b: Raw) -> Raw {
        zip(a, b, |x, y| x - y)
    }
    #[inline(always)]
    pub fn mul(a: Raw, b: Raw) -> Raw {
        zip(a, b, |x, y| x * y)
    }
    #[inline(always)]
    pub fn div(a: Raw, b: Raw) -> Raw {
        zip(a, b, |x, y| x / y)
    }
    #[inline(always)]
    pub fn sqrt(a: Raw) -> Raw {
        map(a, f64::sqrt)
    }
    #[inline(always)]
    pub fn neg(a: Raw) -> Raw {
        map(a, |x| -x)
    }
    #[inline(always)]
    pub fn abs(a: Raw) -> Raw {
        map(a, f64::abs)
    }
    #[inline(always)]
    pub fn lt(a: Raw, b: Raw) -> Raw {
        zip(a, b, |x, y| mask(x < y))
    }
    #[inline(always)]
    pub fn le(a: Raw, b: Raw) -> Raw {
        zip(a, b, |x, y| mask(x <= y))
    }
    #[inline(always)]
    pub fn eq(a: Raw, b: Raw) -> Raw {
        zip(a, b, |x, y| mask(x == y))
    }
    #[inline(always)]
    pub fn is_finite(a: Raw) -> Raw {
        map(a, |x| mask(x.is_finite()))
    }
    #[inline(always)]
    pub fn and(a: Raw, b: Raw) -> Raw {
        zip(a, b, |x, y| mask(set(x) && set(y)))
    }
    #[inline(always)]
    pub fn or(a: Raw, b: Raw) -> Raw {
        zip(a, b, |x, y| mask(set(x) || set(y)))
    }
    #[inline(always)]
    pub fn not(a: Raw) -> Raw {
        map(a, |x| mask(!set(x)))
    }
    #[inline(always)]
    pub fn select(m: Raw, a: Raw, b: Raw) -> Raw {
        [0, 1, 2, 3].map(|k| if set(m[k]) { a[k] } else { b[k] })
    }
    #[inline(always)]
    pub fn bits(m: Raw) -> u32 {
        (0..4).map(|k| u32::from(set(m[k])) << k).sum()
    }
    #[inline(always)]
    pub fn from_bits(bits: u32) -> Raw {
        [0, 1, 2, 3].map(|k| mask(bits >> k & 1 == 1))
    }
}

/// Four `f64` lanes.
#[derive(Clone, Copy, Debug)]
#[repr(transparent)]
pub struct F4(imp::Raw);

/// Four lanes of true or false, the result of a lane-wise comparison.
#[derive(Clone, Copy, Debug)]
#[repr(transparent)]
pub struct M4(imp::Raw);

impl F4 {
    /// All lanes zero.
    #[inline(always)]
    pub fn zero() -> Self {
        Self::splat(0.0)
    }

    /// The same value in every lane.
    #[inline(always)]
    pub fn splat(x: f64) -> Self {
        Self(imp::splat(x))
    }

    /// Lanes 0 to 3 from an array.
    #[inline(always)]
    pub fn new(a: [f64; 4]) -> Self {
        Self(imp::from_array(a))
    }

    /// Each lane's value of `f(lane)`.
    #[inline(always)]
    pub fn from_fn(f: impl FnMut(usize) -> f64) -> Self {
        Self::new(std::array::from_fn(f))
    }

    /// The lanes as an array.
    #[inline(always)]
    pub fn to_array(self) -> [f64; 4] {
        imp::to_array(self.0)
    }

    /// Square root, correctly rounded.
    #[inline(always)]
    pub fn sqrt(self) -> Self {
        Self(imp::sqrt(self.0))
    }

    /// Absolute value (sign bit cleared).
    #[inline(always)]
    pub fn abs(self) -> Self {
        Self(imp::abs(self.0))
    }

    /// `self < other` (false for NaN).
    #[inline(always)]
    pub fn lt(self, other: Self) -> M4 {
        M4(imp::lt(self.0, other.0))
    }

    /// `self <= other` (false for NaN).
    #[inline(always)]
    pub fn le(self, other: Self) -> M4 {
        M4(imp::le(self.0, other.0))
    }

    /// `self > other` (false for NaN).
    #[inline(always)]
    pub fn gt(self, other: Self) -> M4 {
        other.lt(self)
    }

    /// `self >= other` (false for NaN).
    #[inline(always)]
    pub fn ge(self, other: Self) -> M4 {
        other.le(self)
    }

    /// `self == other` (false for NaN; −0 equals +0).
    #[inline(always)]
    pub fn eq(self, other: Self) -> M4 {
        M4(imp::eq(self.0, other.0))
    }

    /// `f64::max` lane by lane: the larger; the other where one is NaN; `self` on a tie.
    #[inline(always)]
    pub fn max(self, other: Self) -> Self {
        other.gt(self).or(!self.eq(self)).select(other, self)
    }

    /// `f64::clamp(lo, hi)` lane by lane (NaN stays NaN).
    #[inline(always)]
    pub fn clamp(self, lo: f64, hi: f64) -> Self {
        let (lo, hi) = (Self::splat(lo), Self::splat(hi));
        let x = self.lt(lo).select(lo, self);
        x.gt(hi).select(hi, x)
    }

    /// Lanes that are neither infinite nor NaN.
    #[inline(always)]
    pub fn is_finite(self) -> M4 {
        M4(imp::is_finite(self.0))
    }
}

impl M4 {
    /// A mask from bit `k` of `bits` for lane `k`.
    #[inline(always)]
    pub fn from_bits(bits: u32) -> Self {
        Self(imp::from_bits(bits))
    }

    /// Bit `k` set where lane `k` is true.
    #[inline(always)]
    pub fn bits(self) -> u32 {
        imp::bits(self.0)
    }

    /// Whether any lane is true.
    #[inline(always)]
    pub fn any(self) -> bool {
        self.bits() != 0
    }

    /// Both masks.
    #[inline(always)]
    pub fn and(self, other: Self) -> Self {
        Self(imp::and(self.0, other.0))
    }

    /// Either mask.
    #[inline(always)]
    pub fn or(self, other: Self) -> Self {
        Self(imp::or(self.0, other.0))
    }

    /// `a` where the mask is true, `b` elsewhere.
    #[inline(always)]
    pub fn select(self, a: F4, b: F4) -> F4 {
        F4(imp::select(self.0, a.0, b.0))
    }

    /// `a` where the mask is true, `b` elsewhere, component by component.
    #[inline(always)]
    pub fn select3(self, a: V4, b: V4) -> V4 {
        V4 {
            x: self.select(a.x, b.x),
            y: self.select(a.y, b.y),
            z: self.select(a.z, b.z),
        }
    }
}

impl std::ops::Not for M4 {
    type Output = M4;
    /// The opposite mask.
    #[inline(always)]
    fn not(self) -> M4 {
        M4(imp::not(self.0))
    }
}

macro_rules! binary {
    ($trait:ident, $method:ident, $f:path) => {
        impl std::ops::$trait for F4 {
            type Output = F4;
            #[inline(always)]
            fn $method(self, rhs: F4) -> F4 {
                F4($f(self.0, rhs.0))
            }
        }
    };
}

binary!(Add, add, imp::add);
binary!(Sub, sub, imp::sub);
binary!(Mul, mul, imp::mul);
binary!(Div, div, imp::div);

impl std::ops::Neg for F4 {
    type Output = F4;
    #[inline(always)]
    fn neg(self) -> F4 {
        F4(imp::neg(self.0))
    }
}

/// Four three-vectors, one per lane, as three lanes of components. Each operation is
/// written as glam's `DVec3` writes it (the same products and sums in the same order).
#[derive(Clone, Copy, Debug)]
pub struct V4 {
    /// x components.
    pub x: F4,
    /// y components.
    pub y: F4,
    /// z components.
    pub z: F4,
}

impl V4 {
    /// All lanes the zero vector.
    #[inline(always)]
    pub fn zero() -> Self {
        Self::splat(DVec3::ZERO)
    }

    /// The same vector in every lane.
    #[inline(always)]
    pub fn splat(v: DVec3) -> Self {
        Self {
            x: F4::splat(v.x),
            y: F4::splat(v.y),
            z: F4::splat(v.z),
        }
    }

    /// Lane `k` is `v[k]`.
    #[inline(always)]
    pub fn new(v: [DVec3; 4]) -> Self {
        Self {
            x: F4::from_fn(|k| v[k].x),
            y: F4::from_fn(|k| v[k].y),
            z: F4::from_fn(|k| v[k].z),
        }
    }

    /// Each lane's vector `f(lane)`.
    #[inline(always)]
    pub fn from_fn(f: impl FnMut(usize) -> DVec3) -> Self {
        Self::new(std::array::from_fn(f))
    }

    /// The lanes as vectors.
    #[inline(always)]
    pub fn to_array(self) -> [DVec3; 4] {
        let (x, y, z) = (self.x.to_array(), self.y.to_array(), self.z.to_array());
        std::array::from_fn(|k| DVec3::new(x[k], y[k], z[k]))
    }

    /// Dot product, `(x x' + y y') + z z'`.
    #[inline(always)]
    pub fn dot(self, rhs: Self) -> F4 {
        (self.x * rhs.x) + (self.y * rhs.y) + (self.z * rhs.z)
    }

    /// Cross product, as glam forms it.
    #[inline(always)]
    pub fn cross(self, rhs: Self) -> Self {
        Self {
            x: self.y * rhs.z - rhs.y * self.z,
            y: self.z * rhs.x - rhs.z * self.x,
            z: self.x * rhs.y - rhs.x * self.y,
        }
    }

    /// Squared length.
    #[inline(always)]
    pub fn length_squared(self) -> F4 {
        self.dot(self)
    }

    /// Length.
    #[inline(always)]
    pub fn length(self) -> F4 {
        self.dot(self).sqrt()
    }

    /// Lanes whose three components equal those of `other`'s (−0 equals +0).
    #[inline(always)]
    pub fn eq(self, other: Self) -> M4 {
        self.x
            .eq(other.x)
            .and(self.y.eq(other.y))
            .and(self.z.eq(other.z))
    }

    /// The vector scaled by `s`, lane by lane (`DVec3 * f64`).
    #[inline(always)]
    pub fn scale(self, s: F4) -> Self {
        Self {
            x: self.x * s,
            y: self.y * s,
            z: self.z * s,
        }
    }
}

impl std::ops::Div<F4> for V4 {
    type Output = V4;
    /// Each component divided by `s` (`DVec3 / f64`).
    #[inline(always)]
    fn div(self, s: F4) -> V4 {
        V4 {
            x: self.x / s,
            y: self.y / s,
            z: self.z / s,
        }
    }
}

impl std::ops::Add for V4 {
    type Output = V4;
    #[inline(always)]
    fn add(self, rhs: V4) -> V4 {
        V4 {
            x: self.x + rhs.x,
            y: self.y + rhs.y,
            z: self.z + rhs.z,
        }
    }
}

impl std::ops::Sub for V4 {
    type Output = V4;
    #[inline(always)]
    fn sub(self, rhs: V4) -> V4 {
        V4 {
            x: self.x - rhs.x,
            y: self.y - rhs.y,
            z: self.z - rhs.z,
        }
    }
}

impl std::ops::Neg for V4 {
    type Output = V4;
    #[inline(always)]
    fn neg(self) -> V4 {
        V4 {
            x: -self.x,
            y: -self.y,
            z: -self.z,
        }
    }
}

impl std::ops::Mul<F4> for V4 {
    type Output = V4;
    #[inline(always)]
    fn mul(self, s: F4) -> V4 {
        self.scale(s)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Awkward values: signed zeros, subnormals, huge and tiny magnitudes, NaN, infinity.
    const VALUES: [f64; 12] = [
        0.0,
        -0.0,
        1.0,
        -2.5,
        1e-310,
        -3e-320,
        1.7e308,
        0.1,
        -7.3e-5,
        f64::NAN,
        f64::INFINITY,
        f64::NEG_INFINITY,
    ];

    fn quads() -> impl Iterator<Item = ([f64; 4], [f64; 4])> {
        (0..VALUES.len()).map(|k| {
            let a = std::array::from_fn(|l| VALUES[(k + l) % VALUES.len()]);
            let b = std::array::from_fn(|l| VALUES[(3 * k + 5 * l + 1) % VALUES.len()]);
            (a, b)
        })
    }

    /// Every lane of every operation has the bits of the scalar operation.
    #[test]
    fn lanes_match_scalar_bit_for_bit() {
        let same = |lanes: F4, scalar: [f64; 4]| {
            for (x, y) in lanes.to_array().iter().zip(scalar) {
                assert!(
                    x.to_bits() == y.to_bits() || (x.is_nan() && y.is_nan()),
                    "{x} vs {y}"
                );
            }
        };
        for (a, b) in quads() {
            let (fa, fb) = (F4::new(a), F4::new(b));
            same(fa + fb, std::array::from_fn(|k| a[k] + b[k]));
            same(fa - fb, std::array::from_fn(|k| a[k] - b[k]));
            same(fa * fb, std::array::from_fn(|k| a[k] * b[k]));
            same(fa / fb, std::array::from_fn(|k| a[k] / b[k]));
            same(fa.sqrt(), a.map(f64::sqrt));
            same(-fa, a.map(|x| -x));
            same(fa.abs(), a.map(f64::abs));
            let bits = |m: M4| m.bits();
            let expect = |f: &dyn Fn(f64, f64) -> bool| -> u32 {
                (0..4).map(|k| u32::from(f(a[k], b[k])) << k).sum()
            };
            assert_eq!(bits(fa.lt(fb)), expect(&|x, y| x < y));
            assert_eq!(bits(fa.le(fb)), expect(&|x, y| x <= y));
            assert_eq!(bits(fa.gt(fb)), expect(&|x, y| x > y));
            assert_eq!(bits(fa.ge(fb)), expect(&|x, y| x >= y));
            assert_eq!(bits(fa.eq(fb)), expect(&|x, y| x == y));
            assert_eq!(bits(fa.is_finite()), expect(&|x, _| x.is_finite()));
            same(fa.max(fb), std::array::from_fn(|k| a[k].max(b[k])));
            same(fa.clamp(-1.0, 1.0), a.map(|x| x.clamp(-1.0, 1.0)));
            let m = fa.lt(fb);
            same(
                m.select(fa, fb),
                std::array::from_fn(|k| if a[k] < b[k] { a[k] } else { b[k] }),
            );
            assert_eq!((!m).bits(), !m.bits() & 0xF);
            assert_eq!(M4::from_bits(m.bits()).bits(), m.bits());
        }
    }

    /// Vector operations have the bits of glam's.
    #[test]
    fn vectors_match_glam_bit_for_bit() {
        let v = |k: usize| {
            DVec3::new(
                0.3 * k as f64 - 1.0,
                -1e-3 / (k as f64 + 0.5),
                (k as f64).sqrt() - 1.5,
            )
        };
        let a: [DVec3; 4] = std::array::from_fn(v);
        let b: [DVec3; 4] = std::array::from_fn(|k| v(k + 7) * 3.1);
        let (va, vb) = (V4::new(a), V4::new(b));
        let same3 = |x: V4, y: [DVec3; 4]| {
            for (p, q) in x.to_array().iter().zip(y) {
                assert_eq!(
                    p.to_array().map(f64::to_bits),
                    q.to_array().map(f64::to_bits)
                );
            }
        };
        same3(va.cross(vb), std::array::from_fn(|k| a[k].cross(b[k])));
        same3(va + vb, std::array::from_fn(|k| a[k] + b[k]));
        same3(va - vb, std::array::from_fn(|k| a[k] - b[k]));
        same3(-va, std::array::from_fn(|k| -a[k]));
        let s = F4::new([0.5, -2.0, 1e-3, 7.0]);
        same3(va * s, std::array::from_fn(|k| a[k] * s.to_array()[k]));
        same3(va / s, std::array::from_fn(|k| a[k] / s.to_array()[k]));
        let dots = va.dot(vb).to_array();
        let lengths = va.length().to_array();
        for k in 0..4 {
            assert_eq!(dots[k].to_bits(), a[k].dot(b[k]).to_bits());
            assert_eq!(lengths[k].to_bits(), a[k].length().to_bits());
        }
        assert_eq!(va.eq(va).bits(), 0xF);
        assert_eq!(va.eq(vb).bits(), 0);
    }
}
